"""The telethermal command, end to end, in process."""

import json

import numpy as np
import pytest

from telethermal.cli import main
from telethermal.data.dataset import load_dataset
from telethermal.physics.contact import contact_flux_w_m2
from telethermal.physics.materials import get_material


def test_scenes_lists_every_shipped_scene(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    for name in ("fingertip-7", "gripper-case-I-cnv", "gripper-case-V"):
        assert name in out


def test_simulate_ideal_is_the_closed_form(tmp_path):
    out = tmp_path / "one"
    assert main(["simulate", "--pad", "skin", "--object", "glass", "--pad-temp-c", "33",
                 "--object-temp-c", "24", "--seconds", "5", "--rate-hz", "100",
                 "--out", str(out), "--ideal"]) == 0
    trial = load_dataset(out)[0]
    t = trial.channels["t_s"]
    exact = contact_flux_w_m2(t, 33.0, 24.0, get_material("skin").effusivity,
                              get_material("glass").effusivity)
    # Written with 3 decimals: 5e-4 W/m^2 of rounding.
    np.testing.assert_allclose(trial.channels["heat_flux_W_m2"], exact, atol=6e-4)
    assert t[0] == pytest.approx(0.01) and len(t) == 500


def test_simulate_non_ideal_starts_at_contact_with_a_lagged_sensor(tmp_path):
    out = tmp_path / "one"
    assert main(["simulate", "--pad", "alumina", "--object", "wood", "--pad-temp-c", "44",
                 "--object-temp-c", "34", "--seconds", "1", "--rate-hz", "1000",
                 "--out", str(out)]) == 0
    flux = load_dataset(out)[0].channels["heat_flux_W_m2"]
    assert abs(flux[0]) < 5.0 and flux[200] > 100.0  # zero through the lag at t = 0


def test_unknown_material_is_a_clear_error(tmp_path, capsys):
    code = main(["simulate", "--pad", "skin", "--object", "cheese", "--pad-temp-c", "33",
                 "--object-temp-c", "24", "--seconds", "1", "--rate-hz", "100",
                 "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert code == 2 and "cheese" in err and "aluminium" in err
    assert not (tmp_path / "x").exists()


def test_bad_numbers_are_refused_by_the_parser(tmp_path):
    with pytest.raises(SystemExit):
        main(["simulate", "--pad", "skin", "--object", "wood", "--pad-temp-c", "nan",
              "--object-temp-c", "24", "--seconds", "1", "--rate-hz", "100",
              "--out", str(tmp_path / "x")])


def test_generate_show_and_validate(tmp_path, capsys):
    scene = tmp_path / "tiny.toml"
    scene.write_text("""
name = "tiny"
room_temp_c = 24.0
sample_rate_hz = 200.0
pre_contact_s = 0.1
[pad]
kind = "peltier"
layers = [["flux_sensor_film", 3.0e-4], ["thermal_grease", 2.0e-5]]
gap_k = 10.0
contact_duration_s = 0.5
trials_per_material = 2
[finger]
persons = 1
trials_per_person = 2
contact_duration_s = 1.0
[[objects]]
material = "glass"
[[objects]]
material = "wood"
""")
    db = tmp_path / "db"
    assert main(["dataset", "generate", "--scene", str(scene), "--out", str(db)]) == 0
    assert json.loads((db / "generation.json").read_text())["datasets"]["pad"]["trials"] == 4
    png = tmp_path / "fig.png"
    assert main(["dataset", "show", str(db), "--out", str(png)]) == 0
    assert png.stat().st_size > 10_000
    assert main(["dataset", "validate", str(db / "pad")]) == 0
    (db / "pad" / "trials" / "wood-01.csv").unlink()
    capsys.readouterr()
    assert main(["dataset", "validate", str(db / "pad")]) == 2
    assert "wood-01.csv" in capsys.readouterr().err
    # A second generate into the same folder is refused without --force.
    assert main(["dataset", "generate", "--scene", str(scene), "--out", str(db)]) == 2
    assert main(["dataset", "generate", "--scene", str(scene), "--out", str(db), "--force"]) == 0


def test_bench_heat_balance_and_plot(tmp_path):
    from telethermal.bench import physics
    from telethermal.physics.scene import load_scene

    balance = physics.heat_balance(load_scene("fingertip-7"))
    assert balance["relative_error"] < 1e-6 and balance["energy_in_j_m2"] > 0
    report = {"rows": [{"model": "layered", "runtime_s": 1e-3, "max_rel_error": 1e-3}],
              "default": {"max_rel_error": 5e-4}, "date": "now", "machine": "here"}
    assert physics.plot(report, tmp_path / "p.png").stat().st_size > 10_000


def test_a_reader_that_closes_the_pipe_gets_no_traceback():
    # ``telethermal identify methods | head -1``: head exits after one line.
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "telethermal", "identify", "methods"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()                  # before the command has written anything
    with proc.stderr:
        err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 1
    assert "Traceback" not in err and "BrokenPipeError" not in err, err
