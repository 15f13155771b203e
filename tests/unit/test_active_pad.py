"""The slave's active pad on CAN (``PAD_*`` frames): the codec round trip
and the driver against its emulator on a virtual bus (set point applied,
status read, watchdog, safe state)."""

import itertools

import pytest
from hypothesis import given
from hypothesis import strategies as st

from telethermal.devices.active_pad import (PAD_CMD, PAD_STATUS, ActivePadDriver,
                                            ActivePadEmulator)

_names = itertools.count()


@given(enable=st.integers(0, 1), pump=st.integers(0, 1), counter=st.integers(0, 15),
       setpoint=st.integers(-5000, 15000), duty=st.integers(0, 250))
def test_a_pad_command_round_trips_on_its_raw_grid(enable, pump, counter, setpoint, duty):
    raw = {"enable": enable, "pump": pump, "counter": counter, "setpoint_c": setpoint,
           "heater_duty": duty, "version": 1}
    data = PAD_CMD.encode(raw, scaling=False)
    assert len(data) == PAD_CMD.length
    assert PAD_CMD.decode(data, scaling=False, decode_choices=False) == raw


@given(bits=st.lists(st.integers(0, 1), min_size=6, max_size=6), counter=st.integers(0, 255),
       actuator=st.integers(-5000, 15000), drive=st.integers(-1000, 1000),
       heatsink=st.integers(-5000, 15000))
def test_a_pad_status_round_trips_on_its_raw_grid(bits, counter, actuator, drive, heatsink):
    raw = dict(zip(("enabled", "over_temp", "sensor_fault", "watchdog", "pump_on",
                    "heater_on"), bits), counter=counter, actuator_c=actuator, drive=drive,
               heatsink_c=heatsink)
    data = PAD_STATUS.encode(raw, scaling=False)
    assert PAD_STATUS.decode(data, scaling=False, decode_choices=False) == raw


@pytest.fixture
def pad():
    clock = [0.0]
    applied = []
    bus = f"virtual:active-pad-test-{next(_names)}"
    emulator = ActivePadEmulator(bus, applied.append, clock=lambda: clock[0], heatsink_c=24.0)
    driver = ActivePadDriver(bus, clock=lambda: clock[0])
    yield clock, applied, emulator, driver
    driver.close()
    emulator.close()


def test_the_driver_commands_the_pad_and_reads_its_status(pad):
    clock, applied, emulator, driver = pad
    assert driver.command(31.5, pump=True, heater_duty=0.5)
    emulator.poll()
    driver.poll()
    assert applied[-1] == pytest.approx(31.5)
    s = driver.status
    assert s.enabled and s.actuator_c == pytest.approx(31.5) and s.pump_on and s.heater_on
    assert driver.healthy and not s.faults


def test_silence_trips_the_pads_watchdog_and_safe_disables_it(pad):
    clock, applied, emulator, driver = pad
    driver.command(36.0)
    emulator.poll()
    clock[0] = 0.2                                      # no command for 200 ms
    emulator.poll()
    driver.poll()
    assert not emulator.enabled and "watchdog" in driver.status.faults
    assert applied[-1] == pytest.approx(emulator.neutral_c)
    assert driver.counters["faults_reported"] == 1 and not driver.healthy
    driver.command(36.0)                                # commands resume: the flag clears
    emulator.poll()
    driver.poll()
    assert emulator.enabled and not driver.status.faults
    driver.safe()
    emulator.poll()
    driver.poll()
    assert not emulator.enabled and not emulator.pump_on and not driver.status.enabled
