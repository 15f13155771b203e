"""``telethermal demo --devices qemu``'s services: master and slave as two
processes whose boards are the reference firmware on emulated STM32F405s
(the display's sensor board and Peltier driver, the slave's version-2
board and active pad driver), against the same touch on the emulated
boards (same seeds). Skipped without QEMU or the cross toolchain, saying
which apt package is missing; failed instead under
``TELETHERMAL_REQUIRE_QEMU=1``.

The services on QEMU run at the demo's ``time_scale`` (their clocks and
the cores' millisecond slowed alike: firmware/README.md, "Processor in the
loop"). What is asserted is what the product owes whatever the host's
speed: the touch named as on the emulated boards and within 1 s of contact
on the slave's sample clock, every byte through the drivers intact, every
command answered, every core on the services' time scale, the only safe
state one a board's own watchdog explains, both services stopping cleanly
and no QEMU left running after a stop, SIGTERM or a killed service. The
issue's accuracy target (flux and skin errors within 10 % of the emulated
boards', no safety event) is measured by ``telethermal demo --devices
qemu`` beside ``--devices emulated`` (bench/results/README.md): how well
the host keeps up at that scale is the host's, and a test asserting it
would test the host.
"""

import signal
import time
from pathlib import Path

import pytest

from telethermal.control.loop import DEFAULT_RATE_HZ
from telethermal.control.safety import Fault
from telethermal.devices import qemu
from telethermal.physics.scene import load_scene, with_finger
from telethermal.services.admin import call
from telethermal.demo.run import Services, demo_time_scale, wait_connected, write_configs
from telethermal.demo.touches import networked_touch
from telethermal.ports import free_ports
from test_firmware_qemu import qemu_or_skip

pytestmark = [pytest.mark.qemu, pytest.mark.slow]
SCENE = with_finger(load_scene("fingertip-7"))


@pytest.fixture(scope="module")
def firmware(tmp_path_factory):
    qemu_or_skip("the services on QEMU")
    build = tmp_path_factory.mktemp("firmware")
    qemu.build_images(build)
    return build


@pytest.fixture(scope="module")
def models(trained_models):
    return trained_models.files(SCENE, 0)


def qemu_pids(build: Path) -> list[int]:
    """The qemu-system-arm processes running images of ``build``."""
    out = []
    for entry in Path("/proc").iterdir():
        try:
            cmd = (entry / "cmdline").read_bytes().split(b"\0")
        except (OSError, ValueError):
            continue
        if cmd and cmd[0].endswith(b"qemu-system-arm") and \
                any(str(build).encode() in part for part in cmd):
            out.append(int(entry.name))
    return out


def wait_gone(build: Path, guard_s: float = 10.0) -> list[int]:
    """The cores still running after ``guard_s`` (a hang guard: a core's
    exit takes a moment after its service's)."""
    deadline = time.monotonic() + guard_s
    while qemu_pids(build) and time.monotonic() < deadline:
        time.sleep(0.1)
    return qemu_pids(build)


def touch(out: Path, models, devices: str, firmware: Path) -> tuple[dict, dict]:
    ports = free_ports(4)
    scale = demo_time_scale(devices, DEFAULT_RATE_HZ, SCENE.sample_rate_hz)
    slave_cfg, master_cfg = write_configs(out, SCENE.name, *models, ports, 0, devices=devices,
                                          firmware_build=str(firmware), time_scale=scale)
    services = Services(out, slave_cfg, master_cfg)
    try:
        wait_connected(services, ports[3], timeout_s=180)
        if devices == "qemu":
            assert len(qemu_pids(firmware)) == 4          # two cores a service
        result = networked_touch(SCENE, "wood", ports, seed=4, contact_s=1.5)
        pad = answered(ports[2]) if devices == "qemu" else {}
    finally:
        codes = services.stop()
    return {**result.summary, "pad_answered": pad}, codes


def answered(slave_admin: int, guard_s: float = 30.0) -> dict:
    """The slave's pad driver's counters once it has had an answer to every
    command it sent (a contact's commands go to the core without waiting,
    so a touch's report can come before their answers); the last counters
    if the guard (a hang guard) runs out."""
    deadline = time.monotonic() + guard_s
    while True:
        pad = call(slave_admin, "status")["devices"]["counters"]["pad"]
        if pad["statuses"] >= pad["sent"] or time.monotonic() > deadline:
            return pad
        time.sleep(0.2)


def test_the_services_on_the_firmware_name_the_touch_as_the_emulated_boards(
        tmp_path, models, firmware):
    emu, emu_codes = touch(tmp_path / "emulated", models, "emulated", firmware)
    pil, codes = touch(tmp_path / "qemu", models, "qemu", firmware)
    assert codes == emu_codes == {"slave": 0, "master": 0}
    assert wait_gone(firmware) == []
    assert pil["devices"] == "qemu" and emu["time_scale"] == 1.0
    assert pil["time_scale"] == demo_time_scale("qemu", DEFAULT_RATE_HZ, SCENE.sample_rate_hz)
    # Every core was told the scale and answered it (QemuBoards refuses otherwise).
    for log in ("master.log", "slave.log"):
        assert "time scale" in (tmp_path / "qemu" / log).read_text()
    assert pil["identified"] == emu["identified"] == "wood"
    assert pil["decision_time_s"] is not None and pil["decision_time_s"] <= 1.0
    # Every byte through the drivers intact, every command answered.
    master, slave = pil["devices_per_side"]["master"], pil["devices_per_side"]["slave"]
    c = pil["device_counters"]
    assert c["board_waits_missed"] == c["answers_missed"] == 0, c
    assert c["bridge_dropped_bytes"] == 0
    assert master["frames"] > 0 and master["crc_errors"] == master["gaps"] == 0
    assert master["garbage"] == master["lost_frames"] == 0
    assert master["peltier_statuses"] >= master["peltier_commands"] > 0
    assert slave["kind"] == "qemu" and slave["frames"] > 0.5 * SCENE.sample_rate_hz
    assert slave["crc_errors"] == slave["gaps"] == slave["boards_lost"] == 0
    assert slave["counters"]["board.frames_v2"] == slave["frames"]
    assert slave["counters"]["answers_missed"] == 0
    assert slave["pad_commands"] > 0
    pad = pil["pad_answered"]
    assert pad["statuses"] >= pad["sent"] > 0 and pad["undecodable"] == 0
    assert abs(slave["precondition"]["reading_c"] - slave["precondition"]["target_c"]) < 0.05
    # A safe state only where the Peltier core's own watchdog disabled the
    # element (a period longer than its 100 ms) and the driver reported it.
    faults = {k for k in pil["safety_event_counts"] if k in {f.value for f in Fault}}
    assert faults <= {Fault.FLUX_NOT_FINITE.value}, pil["safety_event_counts"]
    if pil["safety_events"]:
        assert c["peltier"]["faults_reported"] >= 1 and c["untrusted_periods"] >= 1


@pytest.mark.parametrize("how", ["SIGTERM", "SIGKILL"])
def test_no_core_outlives_its_service(tmp_path, models, firmware, how):
    """SIGTERM: each service stops its cores in its shutdown. SIGKILL (no
    clean-up of any kind): the kernel ends each core with the service
    (PR_SET_PDEATHSIG)."""
    ports = free_ports(4)
    slave_cfg, master_cfg = write_configs(tmp_path, SCENE.name, *models, ports, 0,
                                          devices="qemu", firmware_build=str(firmware))
    services = Services(tmp_path, slave_cfg, master_cfg)
    try:
        wait_connected(services, ports[3], timeout_s=180)
        assert len(qemu_pids(firmware)) == 4
        for proc in services.procs.values():
            proc.send_signal(getattr(signal, how))
        for proc in services.procs.values():
            proc.wait(timeout=60)
    finally:
        services.stop()
    assert wait_gone(firmware) == []
    if how == "SIGTERM":
        for role in ("slave", "master"):
            assert "stopped cleanly" in (tmp_path / f"{role}.log").read_text()
