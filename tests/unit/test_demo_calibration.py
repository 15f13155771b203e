"""``telethermal demo``'s lab calibration (issue 44): a scene without
``[as_built]`` runs as it did (nothing calibrated, nothing said, no file,
no calibration key in either service's config); the calibration file's
path reaches the slave's config under its key ``pad_calibration``. The demo
on a scene with ``[as_built]`` is tests/integration/test_demo_as_built.py."""

from telethermal.physics.scene import load_scene
from telethermal.services import demo as demo_mod
from telethermal.services.config import load_config
from telethermal.services.demo_calibration import (CALIBRATION_FILE, calibrate_as_built,
                                                   path_line)


def test_a_scene_without_as_built_is_not_calibrated(tmp_path):
    lines = []
    assert calibrate_as_built(load_scene("fingertip-7"), tmp_path, 0, lines.append) is None
    assert lines == [] and list(tmp_path.iterdir()) == []


def test_the_demo_on_a_scene_without_as_built_calibrates_nothing(tmp_path, monkeypatch):
    seen = {}

    def models(*args):
        seen["identifier_calibration"] = args[7] if len(args) > 7 else None

    def run(*args, **kw):
        seen["run"] = kw
        return {"touches": [], "exit_codes": {"slave": 0, "master": 0}}

    monkeypatch.setattr(demo_mod, "_demo_models", models)
    monkeypatch.setattr(demo_mod, "run_demo", run)
    lines = []
    result = demo_mod.demo(tmp_path, "fingertip-7", [], echo=lines.append)
    assert seen["identifier_calibration"] is None
    assert (seen["run"]["display_calibration"], seen["run"]["pad_calibration"]) == ("", "")
    assert "calibration" not in result.report
    assert not (tmp_path / CALIBRATION_FILE).exists()
    assert not any("calibrat" in line for line in lines), lines


def test_the_slave_config_names_the_pad_calibration(tmp_path):
    cal = tmp_path / CALIBRATION_FILE
    slave, master = demo_mod.write_configs(tmp_path, "fingertip-7", tmp_path / "i.npz",
                                           tmp_path / "g.npz", [5001, 5002, 5003, 5004], 0,
                                           pad_calibration=str(cal),
                                           slave_pad_calibration=str(cal))
    assert load_config(slave, "slave").pad_calibration == str(cal.resolve())
    assert load_config(master, "master").pad_calibration == str(cal.resolve())
    bare, _ = demo_mod.write_configs(tmp_path, "fingertip-7", tmp_path / "i.npz",
                                     tmp_path / "g.npz", [5001, 5002, 5003, 5004], 0)
    assert load_config(bare, "slave").pad_calibration == ""
    assert path_line("pad_calibration", "") == ""
