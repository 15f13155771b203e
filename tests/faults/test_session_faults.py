"""A real master and slave with the fault proxy between them: the
compensated rendering under 200 ms of delay, and what a 2 s partition in the
middle of a contact leaves behind. Rendering figures only; no wall-clock
figure is asserted."""

import subprocess
import sys

import pytest

from telethermal.physics.scene import load_scene
from telethermal.render.generator import save_generator
from telethermal.services.admin import call
from telethermal.services.demo import (Services, free_ports, networked_touch, wait_connected,
                                       write_configs)
from telethermal.session.models import train_generator, train_identifier
from telethermal.session.run import with_finger

SCENE = with_finger(load_scene("fingertip-7"))


@pytest.fixture(scope="module")
def link(tmp_path_factory):
    out = tmp_path_factory.mktemp("faults")
    ident = train_identifier(SCENE, 0).save(out / "identifier.npz")
    gen = save_generator(train_generator(SCENE, 0), out / "generator.npz")
    s_control, s_stream, p_control, p_stream, s_admin, m_admin = free_ports(6)
    ports = (s_control, s_stream, s_admin, m_admin)
    slave_cfg, master_cfg = write_configs(out, SCENE.name, ident, gen, ports, 0,
                                          security="plain", master_ports=(p_control, p_stream))
    services = Services(out, slave_cfg, master_cfg)
    link = (f'[link]\ncontrol_port = {p_control}\nstream_port = {p_stream}\n'
            f'slave_control_port = {s_control}\nslave_stream_port = {s_stream}\n')
    yield out, services, ports, link
    codes = services.stop()
    assert codes == {"slave": 0, "master": 0}


def touch_through(out, services, ports, link, both: str, seed=5):
    profile = out / "profile.toml"
    profile.write_text(link + "[both]\n" + both)
    proxy = subprocess.Popen([sys.executable, "-m", "telethermal", "faults", "--profile",
                              str(profile)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_connected(services, ports[3], timeout_s=60)
        before = call(ports[3], "status")["counters"]
        result = networked_touch(SCENE, "wood", ports, seed, 2.0).summary
        after = call(ports[3], "status")["counters"]
    finally:
        proxy.terminate()
        proxy.wait(10)
    return result, {k: after[k] - before[k] for k in after}


def test_200_ms_of_delay_renders_safely_and_loses_nothing(link):
    # What holds at 200 ms one way: nothing trips, nothing of the lossless
    # stream is lost, and after identification the flux is still within 5 %
    # of peak. The target (the whole contact within 1.2x of zero
    # delay) is NOT met yet: `bench faults` measures about 2x, because the
    # posteriors the master renders before identification arrive 2 x 200 ms
    # late. It is reported there, not asserted here.
    out, services, ports, text = link
    slow, counters = touch_through(out, services, ports, text, "delay_s = 0.2\n")
    assert slow["flux_rms_error_rel"] < 0.05
    assert slow["safety_events"] == 0
    assert counters["lossless_dropped"] == 0 and counters["invalid"] == 0


def test_a_partition_mid_contact_is_survived_and_counted(link):
    out, services, ports, text = link
    # The proxy starts, the touch begins once connected (~1-2 s later); the
    # blackhole covers 2 s from 2.5 s after the proxy started: mid-contact.
    result, counters = touch_through(out, services, ports, text,
                                     "delay_s = 0.005\npartitions = [[2.5, 2.0]]\n")
    assert result["safety_events"] == 0
    assert counters["lossless_dropped"] == 0 and counters["invalid"] == 0
    # After the partition the link is back: a second touch renders normally.
    again, _ = touch_through(out, services, ports, text, "delay_s = 0.005\n", seed=6)
    assert again["flux_rms_error_rel"] < 0.05 and again["safety_events"] == 0
