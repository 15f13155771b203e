"""The slave's active pad on CAN (``PAD_*`` frames): the codec round trip
and the driver against its emulator on a virtual bus (set point applied,
status read, watchdog, safe state)."""

import itertools

import pytest
from hypothesis import given
from hypothesis import strategies as st

from telethermal.devices.active_pad import (PAD_CMD, PAD_STATUS, ActivePadDriver,
                                            ActivePadEmulator, amps_per_kelvin,
                                            current_junction_c, junction_current_a)

_names = itertools.count()


@given(enable=st.integers(0, 1), pump=st.integers(0, 1), counter=st.integers(0, 15),
       current=st.integers(-32768, 32767), duty=st.integers(0, 250))
def test_a_pad_command_round_trips_on_its_raw_grid(enable, pump, counter, current, duty):
    raw = {"enable": enable, "pump": pump, "counter": counter, "current_a": current,
           "heater_duty": duty, "version": 2}
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
    assert driver.command(-0.35, pump=True, heater_duty=0.5)
    emulator.poll()
    driver.poll()
    assert applied[-1] == pytest.approx(-0.35)
    s = driver.status
    # drive: the current as a fraction of the 8.5 A limit, 0.001 steps.
    assert s.enabled and s.drive == pytest.approx(-0.35 / 8.5, abs=5e-4)
    assert s.pump_on and s.heater_on and driver.healthy and not s.faults


def test_the_pads_module_map_is_its_own_inverse():
    # g = K / (S Tc): about 0.047 A/K for the default module on a 25 C sink.
    assert amps_per_kelvin(25.0) == pytest.approx(0.0466, rel=0.01)
    for junction_c in (10.0, 24.0, 45.0):
        current = junction_current_a(junction_c, 24.0)
        assert (current > 0) == (junction_c < 24.0)          # cooling below the sink
        assert current_junction_c(current, 24.0) == pytest.approx(junction_c)


def test_silence_trips_the_pads_watchdog_and_safe_disables_it(pad):
    clock, applied, emulator, driver = pad
    driver.command(-0.5)
    emulator.poll()
    clock[0] = 0.2                                      # no command for 200 ms
    emulator.poll()
    driver.poll()
    assert not emulator.enabled and "watchdog" in driver.status.faults
    assert applied[-1] == 0.0                           # the safe state: no current
    assert driver.counters["faults_reported"] == 1 and not driver.healthy
    driver.command(-0.5)                                # commands resume: the flag clears
    emulator.poll()
    driver.poll()
    assert emulator.enabled and not driver.status.faults
    driver.safe()
    emulator.poll()
    driver.poll()
    assert not emulator.enabled and not emulator.pump_on and not driver.status.enabled
