"""The slave calibrates its object thermometer at start and on request; a
drifting target is refused and the calibration in force stays."""

import pytest

from telethermal.physics.scene import load_scene, with_finger
from telethermal.services.admin import call
from telethermal.demo.run import Services, wait_connected, write_configs
from telethermal.demo.touches import networked_touch
from telethermal.ports import free_ports

SCENE = with_finger(load_scene("fingertip-7"))


@pytest.fixture(scope="module")
def models(trained_models):
    return trained_models.files(SCENE, 0)


@pytest.mark.slow          # over 10 s here: make test-all and CI run it
def test_calibration_at_start_on_request_and_refused_when_drifting(tmp_path, models):
    ports = free_ports(4)
    slave_cfg, master_cfg = write_configs(tmp_path, SCENE.name, *models, ports, 0)
    services = Services(tmp_path, slave_cfg, master_cfg)
    try:
        wait_connected(services, ports[3])
        at_start = call(ports[2], "status")["thermometer_calibration"]
        # Three pad temperatures, a residual well under the 0.3 K limit.
        assert at_start["calibrated"] and len(at_start["points"]) == 3
        assert at_start["residual_k"] < 0.1 and at_start["error"] is None
        again = call(ports[2], "calibrate_thermometer")
        assert again["ok"] and again["calibrated"] and again["residual_k"] < 0.1
        drifting = call(ports[2], "calibrate_thermometer", drift_k_per_reading=0.02)
        assert drifting["ok"] and not drifting["calibrated"]
        assert "not steady" in drifting["error"]
        status = call(ports[2], "status")["thermometer_calibration"]
        assert status["calibrated"] and status["offset_k"] == again["offset_k"]  # still in force
        assert "not steady" in status["error"]
        result = networked_touch(SCENE, "wood", ports, seed=3, contact_s=1.0)
        assert result.summary["identified"] != "unknown"
    finally:
        codes = services.stop()
    assert codes == {"slave": 0, "master": 0}
    log = (tmp_path / "slave.log").read_text()
    assert "object thermometer (ir) calibrated" in log and "calibration failed" in log
