"""The drivers against their emulators, through the bytes and frames real
devices send: a sensor board on a pty that disappears and comes back,
a Peltier driver on a CAN bus with error frames, bus-off, over-temperature,
a reboot and a silent driver. Every case: a clear error or a counter,
resynchronisation without a restart, NaN (the supervisor's safe state)
where a reading is missing, no crash. Time is a simulated clock."""

import math

import can
import pytest

from telethermal.devices.board import DeviceError, SensorBoard
from telethermal.devices.emulators import PeltierEmulator, SensorBoardEmulator
from telethermal.devices.frames import BoardFrame, encode
from telethermal.devices.peltier import PeltierDriver, parse_bus


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


@pytest.fixture
def board(tmp_path):
    clock = Clock()
    emulator = SensorBoardEmulator(tmp_path / "board")
    driver = SensorBoard(emulator.path, clock=clock, reopen_s=0.1, stale_s=0.05)
    yield emulator, driver, clock
    driver.close()
    emulator.close()


def test_a_board_on_a_pty_reads_like_a_real_tty(board):
    emulator, driver, clock = board
    emulator.send(0.0, -1500.0, 28.3, 4.0)
    flux, temp, force = driver.reading(wait_s=1.0)
    assert flux == pytest.approx(-1500.0, abs=1e-3)          # float32 microvolts
    assert temp == pytest.approx(28.3, abs=0.04)              # NIST inverse: +-0.04 C
    assert force == pytest.approx(4.0)


def test_garbage_bit_flips_and_dropouts_on_the_line_are_counted_and_survived(board):
    emulator, driver, clock = board
    emulator.bit_flips, emulator.dropout = 0.1, 0.1
    good = 0
    for k in range(300):
        clock.t = k * 1e-3
        if k % 50 == 0:
            emulator.garbage(17)
        sent = emulator.send(clock.t, 100.0, 30.0, 2.0)
        reading = driver.poll(wait_s=0.05 if sent else 0.0)
        good += reading is not None
    c = driver.all_counters
    bad = c["crc"] + c["garbage"] + c["version"]
    assert emulator.counters["flipped"] > 10 and emulator.counters["dropped"] > 10
    # A flipped bit is caught by the CRC or breaks the COBS structure; none
    # gets through as a reading.
    assert bad >= emulator.counters["flipped"] - 1
    assert good == c["frames"] and good >= 300 - emulator.counters["dropped"] - bad - 1
    assert c["seq_gaps"] > 0 and c["lost_frames"] >= emulator.counters["dropped"]


def test_a_stuck_channel_flagged_by_the_board_reads_nan(board):
    emulator, driver, clock = board
    emulator.send(0.0, math.nan, 30.0, 2.0)        # the board could not read the flux ADC
    flux, temp, force = driver.reading(wait_s=1.0)
    assert math.isnan(flux) and temp == pytest.approx(30.0, abs=0.04)


def test_a_reading_older_than_stale_s_is_missing(board):
    emulator, driver, clock = board
    emulator.send(0.0, 10.0, 30.0, 2.0)
    assert not math.isnan(driver.reading(wait_s=1.0)[0])
    clock.t = 0.049
    assert not math.isnan(driver.reading()[0])
    clock.t = 0.051                                # nothing new since: stale
    assert all(math.isnan(v) for v in driver.reading())


def test_a_port_that_disappears_and_comes_back_is_reopened_without_a_restart(board):
    emulator, driver, clock = board
    emulator.send(0.0, 10.0, 30.0, 2.0)
    assert driver.poll(wait_s=1.0) is not None
    emulator.disappear()
    clock.t = 0.01
    assert driver.poll(wait_s=0.01) is None                   # lost: counted, no raise
    assert driver.counters["port_lost"] == 1
    assert all(math.isnan(v) for v in driver.reading())
    clock.t = 0.05
    assert driver.poll() is None                              # not yet retried
    clock.t = 0.2
    assert driver.poll() is None and driver.counters["open_failed"] == 1   # still gone
    emulator.reappear()                                        # same path, the board boots
    clock.t = 0.4
    emulator.send(clock.t, 20.0, 31.0, 2.0)
    driver.poll()                                              # reopened now
    emulator.send(clock.t, 20.0, 31.0, 2.0)
    reading = driver.poll(wait_s=1.0)
    assert reading is not None and reading.flux_w_m2 == pytest.approx(20.0, abs=1e-3)
    assert driver.counters["reopened"] == 1


def test_a_port_that_never_existed_is_a_clear_error(tmp_path):
    with pytest.raises(DeviceError, match="cannot open .*no-such-board"):
        SensorBoard(str(tmp_path / "no-such-board"))
    driver = SensorBoard("loop://")
    driver.close()
    with pytest.raises(DeviceError, match="closed"):
        driver.poll()


# pyserial's spy:// never closes its log file (a ResourceWarning at garbage
# collection); that is pyserial's, not ours.
@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_the_driver_takes_any_pyserial_url(board, tmp_path):
    # loop:// echoes what is written: a frame written is a frame read.
    driver = SensorBoard("loop://")
    driver._ser.write(encode(BoardFrame(0, 0, 126.0, 0.0, 25.0, 1.0)))
    assert driver.poll(wait_s=0.5).flux_w_m2 == pytest.approx(100.0)
    driver.close()
    # spy:// around the emulated tty logs the bytes as they pass.
    emulator, _, _ = board
    log = tmp_path / "spy.txt"
    spied = SensorBoard(f"spy://{emulator.path}?file={log}")
    emulator.send(0.0, 100.0, 30.0, 2.0)
    assert spied.poll(wait_s=1.0).flux_w_m2 == pytest.approx(100.0, abs=1e-3)
    spied.close()
    assert "RX" in log.read_text()


# ---------------------------------------------------------------- CAN
@pytest.fixture
def peltier(request):
    clock = Clock()
    applied = []
    bus = f"virtual:test-{request.node.name}"
    emulator = PeltierEmulator(bus, applied.append, clock=clock)
    driver = PeltierDriver(bus, clock=clock)
    yield emulator, driver, clock, applied
    driver.close()
    emulator.close()


def period(emulator, driver, clock, setpoint_c, dt=1e-3):
    clock.t += dt
    driver.command(setpoint_c)
    emulator.poll()
    driver.poll()


def test_setpoints_are_applied_and_reported_with_heartbeats(peltier):
    emulator, driver, clock, applied = peltier
    for _ in range(250):
        period(emulator, driver, clock, 27.5)
    assert applied[-1] == pytest.approx(27.5)
    assert driver.healthy and driver.status.junction_c == pytest.approx(27.5)
    assert driver.counters["heartbeats"] >= 2


def test_error_frames_are_counted_and_change_nothing(peltier):
    emulator, driver, clock, applied = peltier
    period(emulator, driver, clock, 30.0)
    emulator.error_frame()
    period(emulator, driver, clock, 30.0)
    assert driver.counters["error_frames"] == 1 and driver.healthy


def test_bus_off_is_counted_and_the_bus_reopened(peltier, monkeypatch):
    emulator, driver, clock, applied = peltier
    period(emulator, driver, clock, 30.0)

    def bus_off(msg, timeout=None):
        raise can.CanOperationError("Transmit failed: bus-off")

    monkeypatch.setattr(driver.bus, "send", bus_off)
    assert driver.command(30.0) is False                 # counted, not raised
    assert driver.counters["bus_off"] == 1 and not driver.healthy
    clock.t += 0.1
    assert driver.command(30.0) is False                 # before reopen_s
    clock.t += 0.2
    for _ in range(5):
        period(emulator, driver, clock, 31.0)
    assert driver.counters["reopened"] == 1 and driver.healthy
    assert applied[-1] == pytest.approx(31.0)


def test_over_temperature_disables_the_driver_and_is_not_healthy(peltier):
    emulator, driver, clock, applied = peltier
    period(emulator, driver, clock, 40.0)
    emulator.over_temperature()
    period(emulator, driver, clock, 40.0)
    assert "over_temp" in driver.status.faults and not driver.healthy
    assert applied[-1] == pytest.approx(33.0)            # the driver went to neutral itself
    assert driver.counters["faults_reported"] == 1


def test_a_silent_master_trips_the_drivers_watchdog(peltier):
    emulator, driver, clock, applied = peltier
    period(emulator, driver, clock, 40.0)
    clock.t += 0.15                                       # no command for 150 ms
    emulator.poll()
    driver.poll()
    assert emulator.counters["watchdog_trips"] == 1 and applied[-1] == pytest.approx(33.0)
    assert "watchdog" in driver.status.faults
    period(emulator, driver, clock, 40.0)                 # commands again: back
    assert driver.healthy and applied[-1] == pytest.approx(40.0)


def test_a_rebooting_driver_goes_silent_then_is_seen_to_reboot(peltier):
    emulator, driver, clock, applied = peltier
    for _ in range(10):
        period(emulator, driver, clock, 30.0)
    emulator.reboot(offline_s=0.7)
    for _ in range(600):                                   # 0.6 s: no heartbeat
        period(emulator, driver, clock, 30.0)
    assert not driver.alive and not driver.healthy
    for _ in range(200):
        period(emulator, driver, clock, 30.0)
    assert driver.counters["reboots"] == 1 and driver.healthy


def test_a_bad_bus_spec_or_setpoint_is_a_clear_error():
    with pytest.raises(DeviceError, match="use interface:channel"):
        parse_bus("can0")
    with pytest.raises(DeviceError, match="CAN bus 'nosuch:x'"):
        PeltierDriver("nosuch:x")
    driver = PeltierDriver("virtual:bad-setpoint")
    with pytest.raises(DeviceError, match="finite"):
        driver.command(math.nan)
    driver.close()
