"""docker-compose.yml's healthchecks and the waiting touch, run as the
container runs them, against real service processes on loopback (no
engine needed): the master started alone is unhealthy and a touch asked of
it waits; once the slave comes, both healthchecks pass and the touch comes
back identified (issue 28's "master container started alone")."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from telethermal.ports import free_ports
from telethermal.demo.run import write_configs
from telethermal.physics.scene import load_scene, with_finger

ROOT = Path(__file__).resolve().parents[2]


def healthcheck(service: str, ports) -> list[str]:
    """The compose file's healthcheck command for ``service``, pointed at
    this test's admin ports (the containers use the default ones)."""
    test = yaml.safe_load((ROOT / "docker-compose.yml").read_text())["services"][service][
        "healthcheck"]["test"]
    assert test[:3] == ["CMD", "telethermal", "admin"], test
    return [sys.executable, "-m", "telethermal", "admin", "--slave", str(ports[2]),
            "--master", str(ports[3]), *test[3:]]


def probe(argv) -> int:
    return subprocess.run(argv, capture_output=True, timeout=30).returncode


def wait_for(argv, code: int, timeout_s: float) -> float:
    t0 = time.monotonic()
    while probe(argv) != code:
        assert time.monotonic() - t0 < timeout_s, f"{argv} never exited {code}"
        time.sleep(0.5)
    return time.monotonic() - t0


@pytest.fixture
def processes():
    procs = []
    yield procs
    for proc in procs:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
    for proc in procs:
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@pytest.mark.slow          # over 10 s here: make test-all and CI run it
def test_master_alone_is_unhealthy_and_a_touch_waits_for_the_slave(tmp_path, processes,
                                                                   trained_models):
    # (the files `telethermal models --scene fingertip-7` writes: seed 0)
    identifier, generator = trained_models.files(with_finger(load_scene("fingertip-7")), 0)
    ports = free_ports(4)
    slave_cfg, master_cfg = write_configs(tmp_path, "fingertip-7", identifier, generator,
                                          ports, 0, security="plain")
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}

    def start(role, config):
        log = open(tmp_path / f"{role}.log", "w")
        processes.append(subprocess.Popen([sys.executable, "-m", "telethermal", role,
                                           "--config", str(config)], stdout=log,
                                          stderr=subprocess.STDOUT, env=env))
        log.close()

    start("master", master_cfg)
    slave_check, master_check = healthcheck("slave", ports), healthcheck("master", ports)
    # The master answers, but has no session: unhealthy, probe after probe.
    wait_for([*master_check[:8], "status", "master"], 0, 60)        # its admin is up
    assert [probe(master_check) for _ in range(3)] == [1, 1, 1]
    assert probe(slave_check) != 0
    # A touch asked now waits for the session (bounded) ...
    short = subprocess.run([*master_check[:8], "touch", "--contact-s", "1",
                            "--session-wait", "1"], capture_output=True, text=True, timeout=60)
    assert short.returncode == 2, short.stdout + short.stderr
    assert "no session with the slave after waiting 1 s" in " ".join((short.stdout + short.stderr).split()), short.stderr
    touch = subprocess.Popen([*master_check[:8], "touch", "--contact-s", "1.5",
                              "--session-wait", "60", "--material", "wood", "--object-c", "30"],
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    processes.append(touch)
    time.sleep(1.0)
    # ... and the slave comes.
    start("slave", slave_cfg)
    wait_for(slave_check, 0, 90)
    wait_for(master_check, 0, 30)
    out, _ = touch.communicate(timeout=90)
    assert touch.returncode == 0, out
    assert "identified " in out and "against direct contact with wood" in out, out
