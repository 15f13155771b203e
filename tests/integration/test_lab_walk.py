"""A lab's walk from the docs alone (issue 27's target): its own scene file
outside the package (its pad's size, two materials from its own table, two
from the package's), databases generated, exported to CSV in the lab's own
column names and units, imported with --columns/--units and a manifest,
cross-validated by group, then the networked demo on that scene names every
touched material within 1 s, every "unknown" with its reason."""

import csv
import json
from pathlib import Path

import pytest

from telethermal.cli import main

pytestmark = pytest.mark.slow      # the whole guide or walk, command by command (about a minute)

TABLE = """name,role,conductivity_w_mk,density_kg_m3,specific_heat_j_kgk,source
cork,object,0.045,120,1800,"cork board, a supplier's datasheet"
granite,object,2.8,2650,790,"Incropera Table A.3 (granite, Barre)"
"""

SCENE = """name = "lab-pad"
description = "Our 15 x 15 mm pad, two of our materials and two of the package's."
materials = "lab-materials.csv"
room_temp_c = 23.0
sample_rate_hz = 100.0
pre_contact_s = 0.5

[pad]
kind = "peltier"
layers = [["flux_sensor_film", 3.0e-4], ["thermal_grease", 2.0e-5]]
gap_k = 10.0
size_mm = [15.0, 15.0]
contact_duration_s = 2.0
trials_per_material = 6
contact_conductance_w_m2k = 3000.0

[finger]
temp_c = 33.0
persons = 2
trials_per_person = 3

[[objects]]
material = "cork"
[[objects]]
material = "granite"
[[objects]]
material = "aluminium"
[[objects]]
material = "plexiglass"
"""

#: The lab's own names for the dataset's columns, and its units.
THEIRS = {"t_s": "time_ms", "heat_flux_W_m2": "q_kW_m2", "temperature_C": "pad_K",
          "force_N": "press_N"}
SCALE = {"t_s": (1e3, 0.0), "heat_flux_W_m2": (1e-3, 0.0), "temperature_C": (1.0, 273.15),
         "force_N": (1.0, 0.0)}


@pytest.fixture
def own_materials(monkeypatch):
    from telethermal.physics import materials
    monkeypatch.setattr(materials, "_SCENE_MATERIALS", {})
    monkeypatch.setattr(materials, "_PACKAGE_USED", set())


def _export_as_the_lab_would(db: Path, out: Path) -> Path:
    """The generated pad database rewritten in the lab's layout: its column
    names and units, one file per contact, a manifest of file, material,
    group and the temperatures."""
    out.mkdir()
    with (db / "manifest.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    lab_rows = []
    for row in rows:
        with (db / row["file"]).open(newline="") as fh:
            reader = csv.DictReader(fh)
            samples = list(reader)
        name = f"{row['trial_id']}.csv"
        with (out / name).open("w", newline="") as fh:
            w = csv.writer(fh)
            cols = [c for c in THEIRS if c in samples[0]]
            w.writerow([THEIRS[c] for c in cols])
            for s in samples:
                w.writerow([f"{float(s[c]) * SCALE[c][0] + SCALE[c][1]:.9g}" for c in cols])
        lab_rows.append({"file": name, "material": row["material"], "group": row["group"],
                         "T_object_C": row["T_object_C"], "T_pad_C": row["T_pad_C"],
                         "T_room_C": row["T_room_C"]})
    with (out / "manifest.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(lab_rows[0]))
        w.writeheader()
        w.writerows(lab_rows)
    return out / "manifest.csv"


def test_a_lab_walks_from_its_scene_to_a_live_session(tmp_path, own_materials, capsys):
    (tmp_path / "lab-materials.csv").write_text(TABLE)
    scene = tmp_path / "lab-pad.toml"
    scene.write_text(SCENE)
    assert main(["dataset", "generate", "--scene", str(scene), "--out", str(tmp_path / "db"),
                 "--seed", "3"]) == 0
    manifest = _export_as_the_lab_would(tmp_path / "db" / "pad", tmp_path / "lab")
    columns = ",".join(f"{k}={v}" for k, v in THEIRS.items())
    assert main(["dataset", "import", "--manifest", str(manifest), "--into",
                 str(tmp_path / "imported"), "--columns", columns, "--units",
                 "t_s=ms,heat_flux_W_m2=kW/m2,temperature_C=K"]) == 0
    cv = tmp_path / "cv.json"
    assert main(["identify", "cv", "--data", str(tmp_path / "imported"), "--method",
                 "effusivity-lda", "--folds", "4", "--json", str(cv)]) == 0
    report = json.loads(cv.read_text())
    assert report["classes"] == ["aluminium", "cork", "granite", "plexiglass"]
    assert report["trials"] == 24 and report["folds"] == 4
    # Four effusivities 100 to 24,000 W s^0.5/(m^2 K) apart by 4x and more.
    assert report["accuracy_by_window_s"]["1"] == 1.0
    # The slave's models from the lab's pad contacts alone (no finger
    # database: the generator is the scene's direct-contact model).
    assert main(["models", "--scene", str(scene), "--data", str(tmp_path / "imported"),
                 "--out", str(tmp_path / "models")]) == 0
    from telethermal.ident.registry import load_model
    from telethermal.render.generator import load_generator
    ident = load_model(tmp_path / "models" / "identifier.npz")
    assert set(ident.classes_) <= set(load_generator(tmp_path / "models" /
                                                     "generator.npz").materials)
    capsys.readouterr()
    out = tmp_path / "demo"
    # (One of the scene's own materials and one of the package's: the suite's
    # time; `telethermal demo --scene lab-pad.toml --materials
    # cork,granite,aluminium,plexiglass` names all four.)
    assert main(["demo", "--scene", str(scene), "--materials", "cork,aluminium",
                 "--contact-s", "1.5", "--out", str(out), "--seed", "4"]) == 0
    touches = json.loads((out / "demo.json").read_text())["touches"]
    assert [t["material"] for t in touches][:2] == ["cork", "aluminium"]
    for t in touches:
        # (an "unknown" would say why: its reason is in the failure's text)
        assert (t["identified"], t["unknown_reason"]) == (t["material"], None), t
        assert t["decision_time_s"] <= 1.0, t
