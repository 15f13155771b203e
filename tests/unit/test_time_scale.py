"""A service's clock slowed by ``time_scale`` (for boards emulated slower
than real time: QEMU's cores): the clock's arithmetic against a stand-in
for the machine's time, what the transport waits, and what the configs and
the demo accept. No wall-clock figure is asserted."""

import math
from types import SimpleNamespace

import pytest

import telethermal.control.loop as loop_module
from telethermal.control.loop import MAX_TIME_SCALE, RealClock, WorldPausedClock
from telethermal.demo.run import demo_time_scale
from telethermal.errors import ControlError
from telethermal.services.config import ConfigError, MasterConfig, SlaveConfig, load_config
from telethermal.wire.transport import Endpoint, TransportConfig


class MachineTime:
    """The machine's clocks as the loop module reads them: they move only
    when slept on, and each sleep is recorded (the machine's seconds)."""

    def __init__(self, t_s: float = 1000.0):
        self.t_s, self.sleeps = t_s, []

    def perf_counter(self) -> float:
        self.t_s += 1e-7                       # a busy-wait's read moves time a little
        return self.t_s

    monotonic = perf_counter

    def sleep(self, s: float) -> None:
        self.sleeps.append(s)
        self.t_s += s


@pytest.fixture
def machine(monkeypatch):
    m = MachineTime()
    monkeypatch.setattr(loop_module, "time", m)
    return m


@pytest.mark.parametrize("scale", [1.0, 2.5, 10.0])
def test_a_scaled_clock_reads_and_sleeps_scale_times_slower(machine, scale):
    clock = RealClock(spin_s=1e-4, scale=scale)
    assert clock.now() == pytest.approx(machine.t_s / scale, rel=1e-12)
    assert clock.monotonic() == pytest.approx(machine.t_s / scale, rel=1e-12)
    start = clock.now()
    clock.sleep_until(start + 0.002)                 # one 500 Hz period of the clock
    # It slept the period's machine seconds less the spin, then spun the rest.
    assert machine.sleeps == [pytest.approx(0.002 * scale - 1e-4, abs=1e-6)]
    assert clock.now() >= start + 0.002
    assert clock.now() - start == pytest.approx(0.002, abs=1e-6 / scale + 1e-6)


def test_the_spin_stays_in_the_machine_seconds(machine):
    clock = RealClock.for_period(0.002, scale=5.0)
    assert clock.spin_s == pytest.approx(loop_module.SPIN_FRACTION * 0.002)
    assert clock.scale == 5.0


@pytest.mark.parametrize("scale", [0.5, 0.0, -2.0, math.nan, math.inf, MAX_TIME_SCALE * 1.01,
                                   True, "2"])
def test_a_scale_outside_1_to_the_maximum_is_refused(scale):
    with pytest.raises(ControlError, match="scale = .*from 1 \\(real time\\)"):
        RealClock(scale=scale)


def test_a_world_paused_clock_keeps_the_machine_time():
    assert WorldPausedClock.for_period(0.002).scale == 1.0
    with pytest.raises(ControlError, match="machine's time"):
        WorldPausedClock.for_period(0.002, scale=2.0)


def test_the_endpoint_waits_its_clock_time(monkeypatch):
    endpoint = Endpoint("slave", TransportConfig(security="plain", control_port=0,
                                                 stream_port=0), time_scale=4.0)
    try:
        waited = []
        monkeypatch.setattr(endpoint.sockets, "poller",
                            SimpleNamespace(poll=lambda ms: waited.append(ms) or []))
        endpoint.poll(0.01)
        assert waited == [pytest.approx(40.0)]       # ms of the machine's time
    finally:
        endpoint.close()
    with pytest.raises(Exception, match="time_scale must be a finite number >= 1"):
        Endpoint("slave", TransportConfig(security="plain"), time_scale=0.5)


def test_the_configs_take_a_time_scale_only_where_the_devices_wait():
    assert MasterConfig().time_scale == SlaveConfig().time_scale == 1.0
    assert MasterConfig(time_scale=3).time_scale == 3.0            # the simulator
    assert MasterConfig(devices="qemu", time_scale=25).time_scale == 25.0
    assert SlaveConfig(devices="qemu", time_scale=7.5).time_scale == 7.5
    for cls in (MasterConfig, SlaveConfig):
        with pytest.raises(ConfigError, match="devices = 'emulated'.*use 1"):
            cls(devices="emulated", time_scale=2)
        with pytest.raises(ConfigError, match="time_scale = 0.9"):
            cls(time_scale=0.9)
    with pytest.raises(ConfigError, match="at most 99 times"):
        SlaveConfig(devices="qemu", time_scale=99.5)
    with pytest.raises(ConfigError, match="devices = 'hardware'"):
        MasterConfig(devices="hardware", board_url="/dev/ttyUSB0", can_bus="socketcan:can0",
                     time_scale=2)


def test_the_config_file_error_names_the_file_and_the_key(tmp_path):
    path = tmp_path / "master.toml"
    path.write_text('[master]\ndevices = "emulated"\ntime_scale = 4\n')
    with pytest.raises(ConfigError, match=f"{path} \\[master\\]: time_scale = 4(.0)? with devices"):
        load_config(path, "master")


def test_the_demo_slows_qemu_as_far_as_its_uarts_need():
    assert demo_time_scale("sim", 500.0, 100.0) == demo_time_scale("emulated", 500.0, 100.0) \
        == 1.0
    # 70 bytes a 2 ms display period at 0.1 ms a byte, in 40 % of it: 8.75, up.
    assert demo_time_scale("qemu", 500.0, 100.0) == 9.0
    # At 50 Hz the slave's 80-byte sample lines at 100 Hz set it: 2.
    assert demo_time_scale("qemu", 50.0, 100.0) == 2.0
    assert demo_time_scale("sim", 500.0, 100.0, 3.0) == 3.0
    assert demo_time_scale("qemu", 500.0, 100.0, 40.0) == 40.0
    with pytest.raises(ConfigError, match="devices = 'emulated'"):
        demo_time_scale("emulated", 500.0, 100.0, 2.0)
    with pytest.raises(ConfigError, match="time_scale = 0.5"):
        demo_time_scale("qemu", 500.0, 100.0, 0.5)


def test_the_live_view_reads_the_services_clock(monkeypatch, machine):
    """The view's frames are stamped on the feed's clock and placed against
    the services' message times: on a slowed rig the feed runs as slowly."""
    from telethermal.services.viewer import live_feed

    config = MasterConfig(time_scale=4.0, view_port=0, transport=TransportConfig(
        security="plain", control_port=0, stream_port=0))
    feed, _ = live_feed(config)
    try:
        assert feed.clock() == pytest.approx(machine.t_s / 4.0, rel=1e-9)
    finally:
        feed.close()
