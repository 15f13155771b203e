"""A Peltier driver on a serial CAN adapter (SLCAN) that stops taking
bytes: each command fails after a bounded wait instead of holding the
display's loop for ever, counted as a failed send, not as bus-off. The
adapter is a pty (os.openpty) whose other end nobody reads."""

import os
import tty

import pytest

from telethermal.devices.peltier import PeltierDriver


@pytest.fixture
def stuck_adapter():
    master, slave = os.openpty()
    tty.setraw(slave)
    yield os.ttyname(slave)
    os.close(slave)
    os.close(master)


def test_a_stuck_slcan_adapter_fails_the_send_and_is_not_bus_off(stuck_adapter):
    driver = PeltierDriver(f"slcan:{stuck_adapter}", clock=lambda: 0.0)
    try:
        # Each command is a line of about 22 bytes: the pty's buffer fills
        # within a few hundred; the bound only guards the test.
        for _ in range(20_000):
            if not driver.command(1.0):
                break
        else:
            pytest.fail("the adapter took 20,000 commands without a failed send")
        c = driver.counters
        assert c["send_failed"] == 1 and c["bus_off"] == 0, c
        assert driver.bus is None               # to be reopened after reopen_s
    finally:
        driver.close()

