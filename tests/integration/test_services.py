"""Master and slave as two real processes on loopback, over CURVE."""

import math
from pathlib import Path

import pytest

from realclock import assert_rendered, assert_safe_under_load

from telethermal.cli import main
from telethermal.control.loop import DEFAULT_RATE_HZ
from telethermal.physics.scene import load_scene, with_finger
from telethermal.services.config import ConfigError, load_config
from telethermal.demo.run import Services, wait_connected, write_configs
from telethermal.demo.touches import networked_touch
from telethermal.ports import free_ports
from telethermal.services.admin import call
from telethermal.sim.inprocess import run_session, service_sensors
from telethermal.sim.network import NetworkSpec
from telethermal.teleop.memory import memory_counts

SCENE = with_finger(load_scene("fingertip-7"))


@pytest.fixture(scope="module")
def models(trained_models):
    return (*trained_models.files(SCENE, 0), *trained_models.pair(SCENE, 0))


@pytest.mark.parametrize("devices, time_scale", [
    ("sim", 1.0), ("sim", 3.0), pytest.param("emulated", 1.0, marks=pytest.mark.slow)])
def test_two_processes_render_a_touch_and_stop_cleanly(tmp_path, models, devices, time_scale):
    # devices = "emulated": the master's display pad and the slave's sensing
    # pad are read and driven through the serial and CAN drivers and their
    # emulators. time_scale 3: both services' clocks three times slower
    # than the machine's, as under QEMU's cores; the touch the same.
    ident_path, gen_path, identifier, generator = models
    ports = free_ports(4)
    slave_cfg, master_cfg = write_configs(tmp_path, SCENE.name, ident_path, gen_path, ports, 0,
                                          devices=devices, record_dir=tmp_path / "rec",
                                          time_scale=time_scale)
    services = Services(tmp_path, slave_cfg, master_cfg)
    try:
        wait_connected(services, ports[3])
        status = call(ports[2], "status")
        calibration = status["thermometer_calibration"]
        assert status["time_scale"] == call(ports[3], "status")["time_scale"] == time_scale
        result = networked_touch(SCENE, "wood", ports, seed=4, contact_s=1.5)
    finally:
        codes = services.stop()
    s = result.summary
    # The same touch in one process and over the simulated network: the
    # same seed read through the slave service's instruments (its process
    # seed 0) and the calibration it reported.
    sensors = service_sensors(SCENE, 0, calibration)
    local, simulated = (run_session(SCENE, "wood", identifier, generator, contact_s=1.5,
                                    seed=4, slave_sensors=sensors, network=network).summary
                        for network in (None, NetworkSpec()))
    assert codes == {"slave": 0, "master": 0}
    # The touch ran on the real clock: its safety events and its flux error
    # are the machine's load's as much as the code's (tests/realclock.py
    # says where they are counted and asserted instead). What load cannot
    # change: no fault but a stall's, no event without a stall on record;
    # the touch identified as in one process and rendered from it.
    assert_safe_under_load(s, devices)
    assert s["identified"] == local["identified"]
    if devices == "sim":
        # On the simulator the slave's touch is the same trial on every
        # link: the same label, decided at the same instant of the touch
        # (exact: its samples, not the clock the services ran on, decide).
        fields = ("identified", "decision_time_s", "identified_at_s", "object_true_c",
                  "object_ir_c")
        assert {k: s[k] for k in fields} == {k: local[k] for k in fields} \
            == {k: simulated[k] for k in fields}
        assert s["memory_counts"] == local["memory_counts"] == simulated["memory_counts"]
        assert s["decision_time_s"] is not None
    assert s["unknown_reason"] is None            # named: nothing to explain
    assert_rendered(s)
    assert math.isfinite(local["flux_rms_error_rel"])
    assert s["transport"]["invalid"] == 0 and s["transport"]["refused_by_window"] == 0
    assert s["devices"] == devices and s["time_scale"] == time_scale
    if devices == "emulated":
        board = s["device_counters"]["board"]
        # A frame per display period at least over the 1.5 s contact.
        assert board["frames"] > 1.5 * DEFAULT_RATE_HZ
        assert board["crc"] == 0 and board["port_lost"] == 0
        # The slave's side too: its board's version-2 frames, its pad's loop.
        slave = s["devices_per_side"]["slave"]
        assert slave["kind"] == "emulated" and slave["frames"] > 150
        assert slave["crc_errors"] == 0 and slave["boards_lost"] == 0
        assert slave["pad_faults_reported"] == 0          # the pad's watchdog never fired
        assert slave["counters"]["board.frames_v2"] == slave["frames"]
        assert slave["counters"]["preconditions"] == 1
        assert abs(slave["precondition"]["reading_c"] - slave["precondition"]["target_c"]) < 0.05
        assert s["devices_per_side"]["master"]["frames"] > 1.5 * DEFAULT_RATE_HZ
    for role in ("slave", "master"):
        text = (tmp_path / f"{role}.log").read_text()
        assert "stopped cleanly" in text and "safe state" in text
    # Each host recorded the touch; each replays to the same commands and estimates.
    from telethermal.teleop.replay import replay
    (master_rec,) = (tmp_path / "rec").glob("master-*.mcap")
    (slave_rec,) = (tmp_path / "rec").glob("slave-*.mcap")
    assert replay(master_rec)["summary"]["identical"]
    assert replay(slave_rec)["summary"]["slave"]["same_estimates"]


def test_bad_configs_are_refused_with_the_file_and_key(tmp_path, capsys):
    cfg = tmp_path / "m.toml"
    cfg.write_text('[master]\nrate_hz = "fast"\n')
    with pytest.raises(ConfigError, match=r"m.toml \[master\].rate_hz: expected float"):
        load_config(cfg, "master")
    cfg.write_text('[master]\nspeed = 3\n')
    with pytest.raises(ConfigError, match="unknown key 'speed'"):
        load_config(cfg, "master")
    cfg.write_text('[transport]\nhost = "10.0.0.2"\nsecurity = "plain"\n')
    with pytest.raises(ConfigError, match="only on loopback"):
        load_config(cfg, "master")
    cfg.write_text('[master]\n[extra]\n')
    with pytest.raises(ConfigError, match="unknown section"):
        load_config(cfg, "master")
    cfg.write_text('[transport]\nkeys_dir = "nowhere"\n')
    assert main(["master", "--config", str(cfg)]) == 2
    assert "no such key file" in capsys.readouterr().err
    assert main(["slave", "--config", str(tmp_path / "missing.toml")]) == 2


@pytest.mark.parametrize("role, text, message", [
    ("master", "[master]\nrate_hz = nan\n", r"rate_hz = nan: the display loop's rate"),
    ("master", "[master]\nrate_hz = 0.0\n", r"rate_hz = 0.0: the display loop's rate"),
    ("master", "[master]\nrate_hz = 10.0\n",
     r"rate_hz = 10.0: the display loop's rate, from 20 Hz \(two commands inside the Peltier "
     r"driver's 100 ms watchdog\)"),
    ("master", "[master]\nview_port = -5\n", r"view_port = -5: a port is 1-65535 \(0: off\)"),
    ("master", "[master]\nadmin_port = 0\n", r"admin_port = 0: a port is 1-65535$"),
    ("slave", "[slave]\nadmin_port = 70000\n", r"admin_port = 70000: a port is 1-65535"),
    ("slave", "[transport]\ncontrol_port = 99999\n",
     r"\[transport\]: control_port = 99999: a port is 1-65535"),
    ("master", "[transport]\nstream_port = -1\n",
     r"stream_port = -1: a port is 1-65535 \(0: the system picks one\)"),
    ("master", '[master]\ncpus = "1,,x"\n', r"cpus = '1,,x': core numbers and ranges"),
    ("master", "[master]\nrealtime_priority = 120\n", r"realtime_priority = 120: 1-99")])
def test_a_port_or_rate_out_of_range_is_refused_when_the_config_loads(tmp_path, role, text,
                                                                       message):
    """`check` and the services load the file the same way: a port outside
    1-65535 (a socket's bind had raised OverflowError, or a service started
    on port 0), a loop rate that is not a positive number, cores that are
    not numbers and a priority outside SCHED_FIFO's are refused naming the
    file and key (check had passed them, and the master warned at start)."""
    cfg = tmp_path / "c.toml"
    cfg.write_text(text + ("[transport]\nsecurity = \"plain\"\n" if "[transport]" not in text
                           else 'security = "plain"\n'))
    with pytest.raises(ConfigError, match=message) as err:
        load_config(cfg, role)
    assert str(cfg) in str(err.value)


def test_cores_given_as_numbers_or_ranges_load(tmp_path):
    from telethermal.services.config import parse_cpus
    cfg = tmp_path / "c.toml"
    cfg.write_text('[master]\ncpus = "0-1,3"\nrealtime_priority = 20\n'
                   '[transport]\nsecurity = "plain"\n')
    assert parse_cpus(load_config(cfg, "master").cpus) == {0, 1, 3}


def test_shipped_service_configs_load():
    root = Path(__file__).resolve().parents[2] / "services"
    assert load_config(root / "slave" / "config.toml", "slave").transport.security == "curve"
    assert load_config(root / "master" / "config.toml", "master").rate_hz == DEFAULT_RATE_HZ


@pytest.mark.slow          # over 10 s here: make test-all and CI run it
def test_master_and_slave_in_two_network_namespaces(tmp_path, models):
    # Real addresses on a veth pair, separate network stacks: the slave binds
    # 10.231.0.1 in one namespace, the master connects from the other, over
    # CURVE. The admin sockets are Unix sockets (ipc://), which the test
    # reaches from outside both namespaces.
    from telethermal.netns import Namespaces
    reason = Namespaces.why_not()
    if reason:
        pytest.skip(f"cannot make network namespaces here: {reason}")
    ident_path, gen_path, _, _ = models
    admin = (f"ipc://{tmp_path}/slave-admin", f"ipc://{tmp_path}/master-admin")
    with Namespaces() as ns:
        ports = (5600, 5601, *admin)
        slave_cfg, master_cfg = write_configs(tmp_path, SCENE.name, ident_path, gen_path, ports,
                                              0, slave_host=ns.addresses[0])
        services = Services(tmp_path, slave_cfg, master_cfg, namespaces=ns.names)
        try:
            wait_connected(services, admin[1])
            result = networked_touch(SCENE, "plexiglass", ports, seed=2, contact_s=1.0)
        finally:
            codes = services.stop()
    assert codes == {"slave": 0, "master": 0}
    assert_safe_under_load(result.summary)        # real clock: tests/realclock.py
    assert_rendered(result.summary)
    assert result.summary["transport"]["invalid"] == 0
    # Nothing of the namespaces is left behind.
    import subprocess
    left = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    assert all(name not in left for name in ns.names)


def _place(ports, material: str, object_id: str, seed: int) -> dict:
    """Put ``material`` under the slave pad as object ``object_id``; return
    the slave's reply once the master has the announcement (its status)."""
    placed = call(ports[2], "place", material=material, object_id=object_id, seed=seed)
    assert placed["ok"], placed
    _until(lambda: (lambda s: s["object_id"] == object_id and
                    s["object_temp_c"] == placed["object_ir_c"])(call(ports[3], "status")),
           f"the master never heard of object {object_id}")
    return placed


def _touch(ports, seed: int) -> dict:
    result = call(ports[3], "touch", timeout_s=40, contact_s=1.0, seed=seed)
    assert result["ok"], result
    assert_safe_under_load(result)                # real clock: tests/realclock.py
    return result


def _slave_report(ports) -> dict:
    """The slave's report of the touch just over: once its pad is up (the
    master's lift reaches it a network delay after the touch's reply)."""
    _until(lambda: not call(ports[2], "status")["pad_down"], "the slave's pad going up")
    return call(ports[2], "report")


def _until(done, what: str, timeout_s: float = 20.0) -> None:
    """Wait for ``done()`` (a service that does not answer yet: not done)."""
    import time

    from telethermal.errors import TransportError
    end = time.monotonic() + timeout_s
    while True:
        try:
            if done():
                return
        except TransportError:
            pass
        assert time.monotonic() < end, what
        time.sleep(0.05)


@pytest.mark.slow          # over 10 s here: make test-all and CI run it
def test_object_memory_across_objects_a_disagreement_and_a_restart(tmp_path, models):
    # Item 2 of issue 15 on the wire: place object A, touch, identify;
    # place B, touch; place A again: its announcement carries what the slave
    # identified on A, and the master renders it from the touch's start.
    # Then another material under A's name (the fresh identification wins on
    # the master, logged and counted; the slave's memory keeps A's evidence
    # until a second touch in a row disagrees) and a restarted slave (its
    # memory is gone).
    ident_path, gen_path, identifier, generator = models
    ports = free_ports(4)
    slave_cfg, master_cfg = write_configs(tmp_path, SCENE.name, ident_path, gen_path, ports, 0)
    services = Services(tmp_path, slave_cfg, master_cfg)
    slave_status = lambda: call(ports[2], "status")                      # noqa: E731
    try:
        wait_connected(services, ports[3])
        # (Seeds on which the in-process session decides the true material.)
        assert _place(ports, "wood", "cup-a", seed=1)["object_material"] is None
        first = _touch(ports, seed=1)
        assert first["identified"] == "wood" and first["link_counters"]["memory_used"] == 0
        assert _place(ports, "steel", "cup-b", seed=1)["object_material"] is None
        assert _touch(ports, seed=2)["identified"] == "steel"
        again = _place(ports, "wood", "cup-a", seed=2)
        assert again["object_material"] == "wood" and 0 < again["object_confidence"] <= 1
        assert call(ports[3], "status")["object_material"] == "wood"          # as announced
        repeated = _touch(ports, seed=3)
        assert repeated["link_counters"]["memory_used"] == 1
        assert repeated["identified"] == "wood"
        assert repeated["link_counters"]["memory_overruled"] == 0
        assert repeated["memory_judged"] == {"memory_overruled": 0, "memory_kept": 0}
        assert _slave_report(ports)["memory_judged"] == {"memory_overruled": 0, "memory_kept": 0}
        memory = slave_status()["memory"]
        assert {k: v["material"] for k, v in memory.items()} == {"cup-a": "wood",
                                                                "cup-b": "steel"}
        assert memory["cup-a"]["touches"] == 2
        # Steel under the name cup-a: announced as wood, identified steel. The
        # fresh decision wins on the master; the slave's memory weighs it
        # against two wood touches and keeps wood (issue 29)...
        assert _place(ports, "steel", "cup-a", seed=3)["object_material"] == "wood"
        fresh = _touch(ports, seed=4)
        assert fresh["identified"] == "steel"
        assert fresh["link_counters"]["memory_overruled"] == 1
        # This touch's judgement, on each side, as the same touch in one
        # process counts it (the slave's trial: the place's seed, read through
        # the service's instruments; the memory holding wood).
        report = _slave_report(ports)
        assert fresh["memory_judged"] == report["memory_judged"] == {"memory_overruled": 1, "memory_kept": 0}
        local = run_session(SCENE, "steel", identifier, generator, contact_s=1.0, seed=3,
                            expected_material="wood", slave_sensors=service_sensors(
                                SCENE, 0, slave_status()["thermometer_calibration"])).summary
        assert local["memory_counts"] == memory_counts(fresh["memory_judged"],
                                                       report["memory_judged"])
        assert (local["identified"], local["decision_time_s"]) == \
            (report["identified"], report["decision_time_s"])
        status = slave_status()
        assert status["counters"]["memory_overruled"] == 1
        assert status["memory"]["cup-a"]["material"] == "wood"
        assert "kept, now wood" in (tmp_path / "slave.log").read_text()
        # ... until a second steel touch in a row: the object was changed.
        second = _touch(ports, seed=5)
        assert second["identified"] == "steel"
        # The link's counters run over the service's life; a touch's own
        # judgement is counted once, in its own summary, on each side.
        assert second["link_counters"]["memory_overruled"] == 2
        assert second["memory_judged"] == {"memory_overruled": 1, "memory_kept": 0}
        assert _slave_report(ports)["memory_judged"] == {"memory_overruled": 1, "memory_kept": 0}
        status = slave_status()
        assert status["memory"]["cup-a"]["material"] == "steel"
        assert status["memory"]["cup-a"]["touches"] == 2
        assert "replaced, now steel" in (tmp_path / "slave.log").read_text()
        # forget: one object, or all (announced again: the master forgets too);
        # then a restart forgets everything.
        assert "cup-b" not in call(ports[2], "forget", object_id="cup-b")["memory"]
        assert call(ports[3], "status")["object_material"] == "steel"
        assert call(ports[2], "forget")["memory"] == {}
        _until(lambda: call(ports[3], "status")["object_material"] is None,
               "the master was not told the memory was cleared")
        _touch(ports, seed=6)                        # steel on cup-a, remembered again
        assert slave_status()["memory"]["cup-a"]["material"] == "steel"
        services.kill("slave")
        services.start("slave")
        _until(lambda: (lambda s: s.get("ok") and s["peer_alive"])(slave_status()),
               "the restarted slave found no master", 90.0)
        assert slave_status()["memory"] == {}
        assert _place(ports, "steel", "cup-a", seed=7)["object_material"] is None
        assert call(ports[3], "status")["object_material"] is None
    finally:
        codes = services.stop()
    assert codes == {"slave": 0, "master": 0}
