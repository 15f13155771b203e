"""``telethermal demo``'s lab calibration (issue 44): a scene without
``[as_built]`` runs as it did (nothing calibrated, nothing said, no file,
no calibration key in either service's config); the calibration file's
path reaches the slave's config under its key ``pad_calibration``. The demo
on a scene with ``[as_built]`` is tests/integration/test_demo_as_built.py."""

from telethermal.physics.scene import load_scene
from telethermal.demo import run as demo_mod
from telethermal.services.config import load_config
from telethermal.demo.calibration import CALIBRATION_FILE, calibrate_as_built, path_line


def test_a_scene_without_as_built_is_not_calibrated(tmp_path):
    lines = []
    assert calibrate_as_built(load_scene("fingertip-7"), tmp_path, 0, lines.append) is None
    assert lines == [] and list(tmp_path.iterdir()) == []


def test_the_demo_on_a_scene_without_as_built_calibrates_nothing(tmp_path, monkeypatch):
    seen, result, lines = _demo_with(tmp_path, monkeypatch, "")
    assert seen["identifier_calibration"] is None
    assert (seen["run"]["display_calibration"], seen["run"]["pad_calibration"]) == ("", "")
    assert "calibration" not in result.report
    assert not (tmp_path / "out" / CALIBRATION_FILE).exists()
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


def _pad_cal(scene):
    from telethermal.ident.pad_calibration import (CalibratedParameter, PadCalibration,
                                                   pad_digest)
    return PadCalibration(scene.name, pad_digest(scene), (CalibratedParameter(
        ("flux_lag_s",), "flux sensor lag", 1.1, 1.05, 1.15),), (), 3000.0, 1.0, 0.01, 0.1,
        15, ("steel", "wood"))


def _demo_with(tmp_path, monkeypatch, path):
    seen = {}

    def models(*args):
        seen["identifier_calibration"] = args[7] if len(args) > 7 else None

    def run(*args, **kw):
        seen["run"] = kw
        return {"touches": [], "exit_codes": {"slave": 0, "master": 0}}

    monkeypatch.setattr(demo_mod, "_demo_models", models)
    monkeypatch.setattr(demo_mod, "run_demo", run)
    lines = []
    result = demo_mod.demo(tmp_path / "out", "fingertip-7", [], echo=lines.append,
                           calibration=str(path))
    return seen, result, lines


def test_demo_calibration_file_goes_to_each_pad_it_calibrates(tmp_path, monkeypatch):
    """``demo --calibration FILE``: the sensing pad's calibration the file
    holds trains the slave's identifier and reaches the slave's config, its
    ``[display]`` table the master's; a file with one of them gives the
    other service none (before, the file went to the master alone)."""
    import pytest

    from telethermal.errors import CalibrationError
    from telethermal.ident.pad_calibration import write_calibration
    from telethermal.teleop.display_calibration import write_display_calibration
    from telethermal.sim.display_rig import calibrate_simulated

    scene = load_scene("fingertip-7")
    both = write_calibration(_pad_cal(scene), tmp_path / "both.toml")
    write_display_calibration(calibrate_simulated(scene, seed=0), both)
    seen, result, lines = _demo_with(tmp_path, monkeypatch, both)
    assert seen["identifier_calibration"].flux_gain == 1.0
    assert seen["run"]["pad_calibration"] == seen["run"]["display_calibration"] == str(both)
    assert result.report["calibration"]["pad"]["scene"] == "fingertip-7"
    assert any("trained with its pad's" in line for line in lines), lines

    pad_only = write_calibration(_pad_cal(scene), tmp_path / "pad.toml")
    seen, result, _ = _demo_with(tmp_path, monkeypatch, pad_only)
    assert (seen["run"]["pad_calibration"], seen["run"]["display_calibration"]) == (
        str(pad_only), "")
    assert result.report["calibration"]["display"] is None

    display_only = tmp_path / "display.toml"
    write_display_calibration(calibrate_simulated(scene, seed=0), display_only)
    seen, _, _ = _demo_with(tmp_path, monkeypatch, display_only)
    assert seen["identifier_calibration"] is None
    assert (seen["run"]["pad_calibration"], seen["run"]["display_calibration"]) == (
        "", str(display_only))

    neither = tmp_path / "neither.toml"
    neither.write_text("[thermocouple]\noffset_uv = 1.0\n")
    with pytest.raises(CalibrationError, match="neither.toml: neither a sensing pad's"):
        _demo_with(tmp_path, monkeypatch, neither)
