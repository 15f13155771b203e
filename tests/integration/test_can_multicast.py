"""The Peltier driver and its emulator as two processes on python-can's
``udp_multicast`` bus, inside a network namespace this test creates with
nothing but ``lo`` (multicast never leaves it), and removes. The bus is
chosen by interface and channel only, as a lab would choose socketcan:can0."""

import json
import os
import subprocess
import sys
import textwrap

import pytest

from telethermal.netns import Namespaces

NS = f"ttcan{os.getpid() % 100000}"
BUS = "udp_multicast:239.74.163.2"

pytestmark = pytest.mark.skipif(Namespaces.why_not() is not None,
                                reason=str(Namespaces.why_not()))


@pytest.fixture
def namespace():
    steps = [["ip", "netns", "add", NS], ["ip", "-n", NS, "link", "set", "lo", "up"],
             ["ip", "-n", NS, "link", "set", "lo", "multicast", "on"],
             ["ip", "-n", NS, "route", "add", "224.0.0.0/4", "dev", "lo"]]
    try:
        for step in steps:
            subprocess.run(step, check=True, capture_output=True, text=True)
        yield NS
    finally:
        subprocess.run(["ip", "netns", "del", NS], capture_output=True)


DRIVER = textwrap.dedent("""
    import json, time
    from telethermal.devices.peltier import PeltierDriver
    d = PeltierDriver(%r)
    start = next_t = time.monotonic()
    healthy = periods = 0
    while next_t < start + 1.5:                 # a 1 kHz control loop
        d.command(1.25)
        d.poll(0.0)
        if next_t > start + 0.3:
            periods += 1
            healthy += d.healthy
        next_t += 1e-3
        time.sleep(max(0.0, next_t - time.monotonic()))
    s = d.status
    print(json.dumps({"healthy_fraction": healthy / periods,
                      "current_a": s and s.current_a, "counters": d.counters}))
    d.close()
""")


def test_driver_and_emulator_in_two_processes_on_udp_multicast(namespace):
    prefix = ["ip", "netns", "exec", namespace]
    emulator = subprocess.Popen(prefix + [sys.executable, "-m", "telethermal",
                                          "peltier-emulator", "--bus", BUS],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert "emulator on" in emulator.stdout.readline()
        out = subprocess.run(prefix + [sys.executable, "-c", DRIVER % BUS],
                             capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        result = json.loads(out.stdout.strip().splitlines()[-1])
    finally:
        emulator.terminate()
        emulator.communicate(timeout=10)
    # Healthy (heartbeat and status fresh, enabled, no fault) once started:
    # the emulator's heartbeats and statuses came over multicast. In how many
    # of the 1 kHz periods is a real-clock outcome (freshness is judged on
    # the real clock, and a stall of either process on a loaded machine
    # costs periods), not asserted here.
    assert result["healthy_fraction"] > 0, result
    assert result["current_a"] == pytest.approx(1.25)   # reported as driven, 1 mA steps
    assert result["counters"]["heartbeats"] >= 5 and result["counters"]["send_failed"] == 0
