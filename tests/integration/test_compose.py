"""docker-compose.yml: checked by a compose client where one is installed,
else against the Compose Specification schema; and against the project
(the Dockerfile, the configs it names, the services' wiring)."""

import json
import shutil
import subprocess
from pathlib import Path

import jsonschema
import pytest
import yaml

from telethermal.services.config import load_config

ROOT = Path(__file__).resolve().parents[2]
COMPOSE = ROOT / "docker-compose.yml"


def _client():
    if shutil.which("docker-compose"):
        return ["docker-compose"]
    if shutil.which("docker") and subprocess.run(["docker", "compose", "version"],
                                                 capture_output=True).returncode == 0:
        return ["docker", "compose"]
    return None


def test_compose_file_is_valid():
    client = _client()
    if client:
        r = subprocess.run(client + ["-f", str(COMPOSE), "config", "-q"], capture_output=True,
                           text=True, cwd=ROOT)
        assert r.returncode == 0, r.stderr
    schema = json.loads((ROOT / "tests" / "data" / "compose_spec.json").read_text())
    # The schema names draft 2019-09 (with a trailing '#' jsonschema does not
    # resolve): say so explicitly.
    jsonschema.Draft201909Validator(schema).validate(yaml.safe_load(COMPOSE.read_text()))


def test_compose_file_matches_the_project():
    doc = yaml.safe_load(COMPOSE.read_text())
    services = doc["services"]
    assert {"slave", "master"} <= set(services)
    assert (ROOT / services["slave"]["build"]["dockerfile"]).is_file()
    # The master shares the slave's network namespace: loopback between them.
    assert services["master"]["network_mode"] == "service:slave"
    for role in ("slave", "master"):
        command = services[role]["command"]
        assert command[0] == role and command[1] == "--config"
        local = ROOT / "deploy" / "compose" / Path(command[2]).name
        config = load_config(local, role)            # parses, validates (plain on loopback)
        assert config.transport.control_port == 5560
    dockerfile = (ROOT / "deploy" / "Dockerfile").read_text()
    assert "constraints.txt" in dockerfile and "COPY deploy/compose /etc/telethermal" in dockerfile


def test_a_broken_compose_file_is_caught(tmp_path):
    schema = json.loads((ROOT / "tests" / "data" / "compose_spec.json").read_text())
    bad = yaml.safe_load(COMPOSE.read_text())
    bad["services"]["master"]["stop_grace_period"] = {"seconds": 10}
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.Draft201909Validator(schema).validate(bad)
