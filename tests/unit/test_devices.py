"""The drivers against their emulators, through the bytes and frames real
devices send: a sensor board on a pty that disappears and comes back,
a Peltier driver on a CAN bus (protocol version 2: the module current) with
error frames, bus-off, over-temperature, over-current, a reboot, a silent
driver and a version-1 board. Every case: a clear error or a counter,
resynchronisation without a restart, NaN (the supervisor's safe state)
where a reading is missing, no crash. Time is a simulated clock."""

import math

import can
import pytest
from hypothesis import given
from hypothesis import strategies as st

from telethermal.devices.board import DeviceError, SensorBoard
from telethermal.devices.emulators import PeltierEmulator, SensorBoardEmulator
from telethermal.devices.frames import BoardFrame, encode
from telethermal.devices.peltier import (CAN_VERSION, CMD, DEFAULT_CURRENT_LIMIT_A, STATUS,
                                         PeltierDriver, clamp_current_a, parse_bus)


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


def period(emulator, driver, clock, current_a, dt=1e-3):
    clock.t += dt
    driver.command(current_a)
    emulator.poll()
    driver.poll()


def test_currents_are_driven_and_reported_with_heartbeats(peltier):
    emulator, driver, clock, applied = peltier
    for _ in range(250):
        period(emulator, driver, clock, 2.5)
    assert applied[-1] == pytest.approx(2.5)
    assert driver.healthy and driver.status.current_a == pytest.approx(2.5)
    assert driver.counters["heartbeats"] >= 2 and driver.peer_version == CAN_VERSION == 2


def test_a_command_is_clamped_to_the_drivers_limit_and_returns_what_was_sent(peltier):
    emulator, driver, clock, applied = peltier
    assert clamp_current_a(20.0, 8.5) == 8.5 and clamp_current_a(-20.0, 8.5) == -8.5
    assert clamp_current_a(1.5, 8.5) == 1.5 and clamp_current_a(99.0, 1e3) == 32.767
    period(emulator, driver, clock, -20.0)
    assert driver.commanded_a == -DEFAULT_CURRENT_LIMIT_A == -8.5
    assert applied[-1] == pytest.approx(-8.5) and driver.healthy


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_nan_or_infinite_current_is_refused_naming_the_value(peltier, bad):
    emulator, driver, clock, applied = peltier
    sent = driver.counters["sent"]
    with pytest.raises(DeviceError, match=f"current_a={bad!r}"):
        driver.command(bad)
    assert driver.counters["sent"] == sent              # nothing went on the bus


def test_the_status_is_the_simulated_modules_state_quantised_as_the_board_does(request):
    clock = Clock()
    module = [31.23456, 45.6789, 3.21049]
    bus = f"virtual:test-{request.node.name}"
    emulator = PeltierEmulator(bus, lambda i: None, clock=clock, state=lambda: tuple(module))
    driver = PeltierDriver(bus, clock=clock)
    try:
        period(emulator, driver, clock, 3.2)
        s = driver.status
        # 0.01 C and 1 mA steps: the frame's resolution, to within half a step.
        assert (s.junction_c, s.heatsink_c, s.current_a) == (31.23, 45.68, 3.21)
        assert driver.readings() == (31.23, 45.68, 3.21) and not s.warnings
        module[1] = 61.0                                  # the sink saturating: a warning
        period(emulator, driver, clock, 3.2)
        assert driver.status.warnings == ("sink_saturated",) and driver.healthy
    finally:
        driver.close()
        emulator.close()


@pytest.mark.parametrize("module, fault", [((20.0, 30.0, 12.0), "over_current"),
                                           ((20.0, 30.0, -9.5), "over_current"),
                                           ((40.0, 71.0, 2.0), "over_temp"),
                                           ((math.nan, 30.0, 2.0), "sensor_fault")])
def test_the_boards_protection_trips_to_zero_amps_and_the_driver_is_unhealthy(request, module,
                                                                             fault):
    clock = Clock()
    state = [(20.0, 30.0, 2.0)]
    applied = []
    bus = f"virtual:test-{request.node.name}"
    emulator = PeltierEmulator(bus, applied.append, clock=clock, state=lambda: state[0])
    driver = PeltierDriver(bus, clock=clock)
    try:
        period(emulator, driver, clock, 2.0)
        assert driver.healthy
        state[0] = module                      # |I| > 1.1 x 8.5 A, or the sink above 70 C
        period(emulator, driver, clock, 2.0)
        assert driver.status.faults == (fault,) and not driver.healthy
        assert applied[-1] == 0.0 and not emulator.enabled
        assert all(math.isnan(v) for v in driver.readings())
        state[0] = (20.0, 30.0, 0.0)           # the cause has gone: still latched ...
        period(emulator, driver, clock, 2.0)
        assert not driver.healthy and applied[-1] == 0.0
        driver.command(0.0, enable=False)      # ... until the master acknowledges
        period(emulator, driver, clock, 2.0)
        assert driver.healthy and applied[-1] == 2.0
    finally:
        driver.close()
        emulator.close()


def test_error_frames_are_counted_and_change_nothing(peltier):
    emulator, driver, clock, applied = peltier
    period(emulator, driver, clock, 1.0)
    emulator.error_frame()
    period(emulator, driver, clock, 1.0)
    assert driver.counters["error_frames"] == 1 and driver.healthy


def test_bus_off_is_counted_and_the_bus_reopened(peltier, monkeypatch):
    emulator, driver, clock, applied = peltier
    period(emulator, driver, clock, 1.0)

    def bus_off(msg, timeout=None):
        raise can.CanOperationError("Transmit failed: bus-off")

    monkeypatch.setattr(driver.bus, "send", bus_off)
    assert driver.command(1.0) is False                  # counted, not raised
    assert driver.counters["bus_off"] == 1 and not driver.healthy
    clock.t += 0.1
    assert driver.command(1.0) is False                  # before reopen_s
    clock.t += 0.2
    for _ in range(5):
        period(emulator, driver, clock, 1.5)
    assert driver.counters["reopened"] == 1 and driver.healthy
    assert applied[-1] == pytest.approx(1.5)


def test_over_temperature_disables_the_driver_and_is_not_healthy(peltier):
    emulator, driver, clock, applied = peltier
    period(emulator, driver, clock, -2.0)
    emulator.over_temperature()
    period(emulator, driver, clock, -2.0)
    assert "over_temp" in driver.status.faults and not driver.healthy
    assert applied[-1] == 0.0                            # the board cut the current itself
    assert driver.counters["faults_reported"] == 1


def test_a_silent_master_trips_the_drivers_watchdog(peltier):
    emulator, driver, clock, applied = peltier
    period(emulator, driver, clock, 2.0)
    clock.t += 0.15                                       # no command for 150 ms
    emulator.poll()
    driver.poll()
    assert emulator.counters["watchdog_trips"] == 1 and applied[-1] == 0.0
    assert "watchdog" in driver.status.faults
    period(emulator, driver, clock, 2.0)                  # commands again: back
    assert driver.healthy and applied[-1] == pytest.approx(2.0)


def test_a_driver_that_stops_reporting_is_unhealthy_within_its_heartbeat_timeout(peltier):
    emulator, driver, clock, applied = peltier
    for _ in range(300):
        period(emulator, driver, clock, 2.0)
    assert driver.healthy
    silent_from = clock.t                                 # the board hangs: no frame at all
    while driver.healthy:
        clock.t += 1e-3
        driver.command(2.0)
        driver.poll()
    assert clock.t - silent_from <= driver.heartbeat_timeout_s + 1e-9
    assert all(math.isnan(v) for v in driver.readings())


def test_a_rebooting_driver_goes_silent_then_is_seen_to_reboot(peltier):
    emulator, driver, clock, applied = peltier
    for _ in range(10):
        period(emulator, driver, clock, 1.0)
    emulator.reboot(offline_s=0.7)
    for _ in range(600):                                   # 0.6 s: no heartbeat
        period(emulator, driver, clock, 1.0)
    assert not driver.alive and not driver.healthy
    for _ in range(200):
        period(emulator, driver, clock, 1.0)
    assert driver.counters["reboots"] == 1 and driver.healthy


def test_a_version_1_board_is_refused_with_an_error_naming_both_versions(request, caplog):
    clock = Clock()
    applied = []
    bus = f"virtual:test-{request.node.name}"
    old = PeltierEmulator(bus, applied.append, clock=clock, version=1)
    driver = PeltierDriver(bus, clock=clock)
    try:
        for _ in range(300):
            period(old, driver, clock, 2.0)
        # The old board reads bytes 1-2 as a set point: it refuses the command
        # by its version byte and drives nothing; we refuse it by its heartbeat.
        assert applied == [] and old.counters["bad_commands"] == old.counters["commands"] > 0
        assert not driver.healthy and driver.peer_version == 1
        assert "version 1" in driver.version_error and "version 2" in driver.version_error
        assert driver.counters["version_mismatch"] >= 3
        assert "speaks CAN protocol version 1" in caplog.text
    finally:
        driver.close()
        old.close()


def test_a_version_1_command_is_refused_by_a_version_2_board(peltier):
    emulator, driver, clock, applied = peltier
    period(emulator, driver, clock, 1.0)
    statuses, drives = driver.counters["statuses"], len(applied)
    # A version-1 master's frame: enable, a 40.00 C set point, version 1.
    old = bytes([0x11]) + (4000).to_bytes(2, "little", signed=True) + bytes([1])
    raw = can.Bus(interface="virtual", channel=driver.spec.split(":", 1)[1])
    try:
        raw.send(can.Message(arbitration_id=CMD.frame_id, data=old, is_extended_id=False))
        clock.t += 1e-3
        emulator.poll()
        driver.poll()
    finally:
        raw.shutdown()
    assert emulator.counters["bad_commands"] == 1
    assert driver.counters["statuses"] == statuses and len(applied) == drives   # not answered


@given(enable=st.integers(0, 1), counter=st.integers(0, 15),
       current=st.integers(-32768, 32767), version=st.integers(0, 255))
def test_a_command_round_trips_on_its_raw_grid(enable, counter, current, version):
    raw = {"enable": enable, "counter": counter, "current_a": current, "version": version}
    data = CMD.encode(raw, scaling=False)
    assert len(data) == CMD.length == 4 and data[3] == version     # where every version has it
    assert CMD.decode(data, scaling=False, decode_choices=False) == raw
    assert int.from_bytes(data[1:3], "little", signed=True) == current   # mA, int16 LE


@given(bits=st.lists(st.integers(0, 1), min_size=6, max_size=6), counter=st.integers(0, 255),
       junction=st.integers(-5000, 15000), current=st.integers(-32768, 32767),
       heatsink=st.integers(-5000, 15000))
def test_a_status_round_trips_on_its_raw_grid(bits, counter, junction, current, heatsink):
    raw = dict(zip(("enabled", "over_temp", "over_current", "sensor_fault", "watchdog",
                    "sink_saturated"), bits), counter=counter, junction_c=junction,
               current_a=current, heatsink_c=heatsink)
    data = STATUS.encode(raw, scaling=False)
    assert STATUS.decode(data, scaling=False, decode_choices=False) == raw
    assert data[0] == sum(b << i for i, b in enumerate(bits))


def test_a_bad_bus_spec_or_limit_is_a_clear_error():
    with pytest.raises(DeviceError, match="use interface:channel"):
        parse_bus("can0")
    with pytest.raises(DeviceError, match="CAN bus 'nosuch:x'"):
        PeltierDriver("nosuch:x")
    with pytest.raises(DeviceError, match="current_limit_a must be > 0 A, got nan"):
        PeltierDriver("virtual:bad-limit", current_limit_a=math.nan)


# ---------------------------------------------------------------- the display
class FakeTouch:
    """A touch that records what it is driven with and reports a module state."""

    def __init__(self):
        self.steps, self.state = [], (30.0, 27.5, 0.0)

    def sense(self, t_s):
        from telethermal.devices.readings import PadSensors
        return PadSensors(0.0, 30.0, 0.0)

    def actuate(self, t_s, step, dt_s, force_n):
        self.steps.append(step)
        self.state = (30.0 - step.current_a, 27.5, step.current_a)   # any physics will do

    def module_state(self):
        return self.state


def test_the_emulated_display_drives_the_touch_with_the_current_the_board_applied():
    import math as _math

    from telethermal.devices.display import EmulatedDisplay
    from telethermal.teleop.master import MasterStep

    clock, touch = Clock(), FakeTouch()
    d = EmulatedDisplay(touch, clock=clock)
    try:
        for k, current in enumerate([1.5] * 5 + [20.0] * 5):
            clock.t = k * 1e-3
            d.read(clock.t)
            d.apply(clock.t, MasterStep(clock.t, "contact", True, _math.nan, 33.0, 33.0, False,
                                        current), 1e-3, 0.0)
        # The step's other fields pass through; current_a is what the board drove
        # (the request clamped to the 8.5 A limit).
        assert [s.current_a for s in touch.steps] == [1.5] * 5 + [8.5] * 5
        assert touch.steps[-1].junction_applied_c == 33.0
        d.read(clock.t)
        assert d.module_readings() == (21.5, 27.5, 8.5)     # the touch's module, via CAN
        d.peltier_emulator.trip("over_current")
        clock.t += 1e-3
        d.read(clock.t)
        d.apply(clock.t, MasterStep(clock.t, "contact", True, _math.nan, 33.0, 33.0, False,
                                    2.0), 1e-3, 0.0)
        assert touch.steps[-1].current_a == 0.0              # the board's safe state
        assert all(_math.isnan(v) for v in d.module_readings())
        with pytest.raises(DeviceError, match="current_a=nan"):
            d.apply(clock.t, MasterStep(clock.t, "contact", True, _math.nan, 33.0, 33.0,
                                        False, _math.nan), 1e-3, 0.0)
    finally:
        d.close()


def test_a_stalled_master_loop_is_the_emulated_boards_watchdog_and_an_untrusted_flux():
    # What test_services allows on a loaded machine, and only with this
    # explanation: the loop stalls past the Peltier board's watchdog, the
    # board disables itself, the display reads its flux as untrusted (NaN:
    # the supervisor's safe state) and its counters say why.
    import math as _math

    from telethermal.devices.display import EmulatedDisplay
    from telethermal.teleop.master import MasterStep

    clock, touch = Clock(), FakeTouch()
    d = EmulatedDisplay(touch, clock=clock)

    def period():
        reading = d.read(clock.t)
        d.apply(clock.t, MasterStep(clock.t, "contact", True, _math.nan, 33.0, 33.0, False,
                                    1.0), 1e-3, 0.0)
        clock.t += 1e-3
        return reading

    try:
        for _ in range(20):
            reading = period()
        assert _math.isfinite(reading.flux_w_m2)
        assert d.counters()["driver_board"]["watchdog_trips"] == 0
        clock.t += 0.15                                   # the loop stalls 150 ms
        assert _math.isnan(period().flux_w_m2)
        assert d.counters()["driver_board"]["watchdog_trips"] == 1
    finally:
        d.close()
