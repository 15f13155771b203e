"""A lab's CSV files into the dataset format (data/csv_import.py, issue 27):
columns mapped and units converted, the onset found or given, and every bad
input an error naming the file, the line and the column; nothing written
when anything is wrong."""

import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from telethermal.cli import main
from telethermal.data.csv_import import CsvSpec, read_lab_csv
from telethermal.data.dataset import load_dataset
from telethermal.errors import DatasetError

RATE = 100.0


def lab_file(path, n=120, rate=RATE, start_s=-0.2, delimiter=",", decimal=".", bom=False,
             header=("time_ms", "q_kW", "T_pad", "F")):
    """A lab's file: time in ms, flux in kW/m2 (q ~ 1/sqrt(t) after contact),
    pad temperature, force (10 N in contact)."""
    t = start_s + np.arange(n) / rate
    q = np.where(t >= 0, -4.0 / np.sqrt(np.maximum(t, 0.0) + 0.01), 0.0)
    temp = 34.0 + np.where(t >= 0, -2.0, 0.0)
    force = np.where(t >= 0, 10.0, 0.0)
    rows = [delimiter.join(header)]
    for row in zip(1e3 * t, q, temp, force):
        rows.append(delimiter.join(f"{v:.6f}".replace(".", decimal) for v in row))
    path.write_text(("\ufeff" if bom else "") + "\n".join(rows) + "\n", encoding="utf-8")
    return t, q


COLUMNS = "t_s=time_ms,heat_flux_W_m2=q_kW,temperature_C=T_pad,force_N=F"
UNITS = "t_s=ms,heat_flux_W_m2=kW/m2"


@pytest.mark.parametrize("delimiter, decimal, bom", [(",", ".", False), (";", ",", True),
                                                      ("\t", ",", False)])
def test_columns_mapped_and_units_converted_whatever_the_separators(tmp_path, delimiter,
                                                                    decimal, bom):
    t, q = lab_file(tmp_path / "glass_1.csv", delimiter=delimiter, decimal=decimal, bom=bom)
    ch = read_lab_csv(tmp_path / "glass_1.csv", CsvSpec.from_options(COLUMNS, UNITS))
    np.testing.assert_allclose(ch["t_s"], t, atol=1e-9)                 # ms -> s
    np.testing.assert_allclose(ch["heat_flux_W_m2"], 1e3 * q, rtol=1e-6, atol=1e-3)


def test_import_then_train_a_lab_dataset_at_another_rate_than_the_scene(tmp_path, capsys):
    # Two materials, two groups each, sampled at 250 Hz (the scene: 100 Hz).
    for m, scale in (("glass", 1.0), ("cork", 0.2)):
        for g in ("alice", "bob"):
            for k in range(3):
                f = tmp_path / "lab" / f"{m}_{g}_{k}.csv"
                f.parent.mkdir(exist_ok=True)
                t, q = lab_file(f, n=300, rate=250.0, start_s=0.0)      # no pre-contact
                text = f.read_text().splitlines()
                f.write_text("\n".join(text[:1] + [
                    ",".join([*r.split(",")[:1], f"{float(r.split(',')[1]) * scale * (1 + 0.01 * k):.6f}",
                              *r.split(",")[2:]]) for r in text[1:]]) + "\n")
    manifest = tmp_path / "lab" / "manifest.csv"
    manifest.write_text("file,material,group,T_object_C\n" + "".join(
        f"{m}_{g}_{k}.csv,{m},{g},24.0\n" for m in ("glass", "cork") for g in ("alice", "bob")
        for k in range(3)))
    into = tmp_path / "ds"
    assert main(["dataset", "import", "--manifest", str(manifest), "--into", str(into),
                 "--columns", COLUMNS, "--units", UNITS, "--pad-c", "34", "--room-c", "22"]) == 0
    trials = load_dataset(into)
    assert len(trials) == 12 and {t.sample_rate_hz for t in trials} == {250.0}
    assert {t.group for t in trials} == {"alice", "bob"} and trials[0].gap_k == 10.0
    # The onset: the first sample with force >= 1 N (the file's time starts at 0).
    assert trials[0].channels["t_s"][0] == 0.0
    assert main(["identify", "train", "--data", str(into), "--method", "effusivity-lda",
                 "--out", str(tmp_path / "m.npz")]) == 0
    assert main(["identify", "cv", "--data", str(into), "--method", "effusivity-lda",
                 "--folds", "2"]) == 0
    assert "2 folds by group (2 groups, 12 trials)" in capsys.readouterr().out
    # The model names no scene (the lab's data do not): a scene without its
    # materials refuses it, naming them.
    from telethermal.errors import ModelFileError
    from telethermal.ident.registry import load_model
    from telethermal.physics.scene import load_scene
    from telethermal.teleop.slave import slave_rng
    from telethermal.teleop.slave import Slave

    model = load_model(tmp_path / "m.npz")
    assert model.scene_ is None
    with pytest.raises(ModelFileError, match=r"trained on data that name no scene, on cork, "
                                             r"glass; scene 'fingertip-7' has objects of "
                                             r"aluminium.*: cork, glass are not among them"):
        Slave(load_scene("fingertip-7"), "wood", model, slave_rng(0))


def _cell(text: str, line: int, column: int, value: str) -> str:
    """``text`` with the cell at file line ``line`` (1: the header), ``column`` replaced."""
    lines = text.splitlines()
    cells = lines[line - 1].split(",")
    cells[column] = value
    lines[line - 1] = ",".join(cells)
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("damage, message", [
    (lambda s: s.replace("time_ms", "clock"), r"no t_s \(column 'time_ms'\).*its header: "
                                               r"clock, q_kW"),
    (lambda s: s.replace("q_kW", "heat"), r"no heat_flux_W_m2 \(column 'q_kW'\)"),
    (lambda s: _cell(s, 6, 1, "x0.5"), r"line 6, column 'q_kW': 'x0\.5' is not a number"),
    (lambda s: "\n".join(s.splitlines()[:30] + [s.splitlines()[2]] + s.splitlines()[30:]),
     r"line 31, column 'time_ms': the time restarts \(0\.08 then -0\.19\): one contact "
     r"per file"),
    (lambda s: "\n".join(s.splitlines()[:20] + s.splitlines()[40:]),
     r"line 21: a gap in the time"),
    (lambda s: s.replace(",10.000000\n", ",10.000000,1\n", 1), r"line \d+: 5 cells, 4 columns"),
])
def test_bad_files_are_named_by_line_and_column(tmp_path, capsys, damage, message):
    f = tmp_path / "lab.csv"
    lab_file(f)
    f.write_text(damage(f.read_text()))
    into = tmp_path / "ds"
    assert main(["dataset", "import", str(f), "--into", str(into), "--columns", COLUMNS,
                 "--units", UNITS, "--material", "glass", "--group", "g", "--object-c", "24",
                 "--pad-c", "34", "--room-c", "22"]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "lab.csv" in err
    assert re.search(message, err), err
    assert not into.exists()                                       # nothing half-written


def test_missing_per_trial_values_and_options_are_named(tmp_path, capsys):
    f = tmp_path / "lab.csv"
    lab_file(f)
    args = ["dataset", "import", str(f), "--into", str(tmp_path / "ds"), "--columns", COLUMNS,
            "--units", UNITS, "--material", "glass", "--group", "g", "--pad-c", "34",
            "--room-c", "22"]
    assert main(args) == 2
    assert "no T_object_C given (--object-c or a manifest column 'T_object_C')" in \
        " ".join(capsys.readouterr().err.split())
    assert main(args + ["--object-c", "24", "--units", "heat_flux_W_m2=mW"]) == 2
    assert "heat_flux_W_m2 takes W/m2, kW/m2, W/cm2" in capsys.readouterr().err
    assert main(args + ["--object-c", "24", "--columns", "flux=q_kW"]) == 2
    assert "--columns 'flux': not a dataset column" in " ".join(capsys.readouterr().err.split())


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=3, max_size=8),
       st.sampled_from([(",", "."), (";", ",")]))
def test_any_numbers_survive_the_separators(tmp_path_factory, values, sep):
    delimiter, decimal = sep
    path = tmp_path_factory.mktemp("h") / "x.csv"
    lines = [delimiter.join(["t_s", "heat_flux_W_m2"])] + [
        delimiter.join([f"{0.01 * i:.2f}".replace(".", decimal),
                        repr(v).replace(".", decimal)]) for i, v in enumerate(values)]
    path.write_text("\n".join(lines))
    ch = read_lab_csv(path, CsvSpec({}, {}))
    np.testing.assert_array_equal(ch["heat_flux_W_m2"], np.array(values))
    with pytest.raises(DatasetError):
        read_lab_csv(path, CsvSpec({"force_N": "F"}, {}))


def test_the_onset_inside_a_file_from_its_force_or_given(tmp_path):
    # The file's time starts at 0 with 20 samples before contact: the onset
    # is the first force >= 1 N (sample 20), or what --onset-s says.
    from telethermal.data.csv_import import lab_trial

    f = tmp_path / "late.csv"
    lab_file(f, n=120, start_s=-0.2)
    text = f.read_text().splitlines()
    # shift the file's clock: time in ms from 0 (the contact at 200 ms)
    f.write_text("\n".join(text[:1] + [",".join([f"{float(r.split(',')[0]) + 200.0:.6f}",
                                                  *r.split(",")[1:]]) for r in text[1:]]) + "\n")
    spec = CsvSpec.from_options(COLUMNS, UNITS)
    values = {"material": "glass", "group": "g", "T_object_C": 24, "T_pad_C": 34,
              "T_room_C": 22}
    found = lab_trial(f, spec, values, 0)
    assert found.channels["t_s"][20] == pytest.approx(0.0, abs=1e-9)
    assert found.channels["t_s"][0] == pytest.approx(-0.2, abs=1e-9)
    given_ = lab_trial(f, spec, {**values, "onset_s": "0,25"}, 0)   # a decimal comma too
    assert given_.channels["t_s"][25] == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(DatasetError, match=r"late\.csv: onset_s 'soon' is not a number"):
        lab_trial(f, spec, {**values, "onset_s": "soon"}, 0)
    with pytest.raises(DatasetError, match=r"material '\.\./x': letters, digits"):
        lab_trial(f, spec, {**values, "material": "../x"}, 0)


def test_line_numbers_count_blank_lines_and_one_file_is_imported_once(tmp_path, capsys):
    f = tmp_path / "lab" / "a.csv"
    f.parent.mkdir()
    lab_file(f)
    lines = f.read_text().splitlines()
    cells = lines[4].split(",")
    lines[4] = ",".join([cells[0], "bad", *cells[2:]])                 # file line 5
    f.write_text("\n".join(lines[:2] + [""] + lines[2:]) + "\n")       # a blank line 3
    with pytest.raises(DatasetError, match=r"a\.csv line 6, column 'q_kW': 'bad'"):
        read_lab_csv(f, CsvSpec.from_options(COLUMNS, UNITS))
    lab_file(f)
    (tmp_path / "lab" / "manifest.csv").write_text("file,material,group\na.csv,glass,g1\n")
    # The same file on the command line (spelt another way) and in the manifest: once.
    into = tmp_path / "ds"
    assert main(["dataset", "import", str(tmp_path / "lab" / ".." / "lab" / "a.csv"),
                 "--manifest", str(tmp_path / "lab" / "manifest.csv"), "--into", str(into),
                 "--columns", COLUMNS, "--units", UNITS, "--object-c", "24", "--pad-c", "34",
                 "--room-c", "22"]) == 0
    trials = load_dataset(into)
    assert len(trials) == 1 and trials[0].group == "g1"
    # Again: the same contact, refused as imported before.
    assert main(["dataset", "import", str(f), "--into", str(into), "--columns", COLUMNS,
                 "--units", UNITS, "--material", "glass", "--group", "g1", "--object-c", "24",
                 "--pad-c", "34", "--room-c", "22"]) == 2
    assert "imported before?" in capsys.readouterr().err


@pytest.mark.parametrize("damage, options, message", [
    # A 200 KB quoted cell: over the csv module's 128 KiB (a bare _csv.Error before).
    (lambda s: _cell(s, 6, 3, '"' + "x" * 200_000 + '"'), [], r"line 6: not CSV: field larger"),
    # 1e308 kW/m^2: inf once converted; 1e307 W/m^2 would be finite, still refused.
    (lambda s: _cell(s, 9, 1, "1e308"), [],
     r"line 9, column 'q_kW': heat_flux_W_m2 = inf is outside \[-1e\+06, 1e\+06\]"),
    (lambda s: _cell(s, 9, 1, "5e3"), [],
     r"line 9, column 'q_kW': heat_flux_W_m2 = 5e\+06 is outside"),
    (lambda s: _cell(s, 7, 2, "-300"), [], r"line 7, column 'T_pad': temperature_C = -300"),
    (lambda s: s, ["--material", "m" * 10_000], r"material 'm+'\.\.\.: 10000 characters, over 64"),
])
def test_limits_of_a_lab_file_are_named(tmp_path, capsys, damage, options, message):
    f = tmp_path / "lab.csv"
    lab_file(f)
    f.write_text(damage(f.read_text()))
    into = tmp_path / "ds"
    args = ["dataset", "import", str(f), "--into", str(into), "--columns", COLUMNS,
            "--units", UNITS, "--material", "glass", "--group", "g", "--object-c", "24",
            "--pad-c", "34", "--room-c", "22", *options]
    assert main(args) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "lab.csv" in err and re.search(message, err), err[:500]
    assert not into.exists()                                       # nothing half-written


def test_import_into_a_folder_that_is_not_a_dataset_is_refused_and_loses_nothing(tmp_path,
                                                                                  capsys):
    """--into is a dataset, an empty folder or a new path: a generated
    database folder (pad/ and finger/), a folder of other files or a file
    (the lab's own CSV) would have been replaced by the dataset; each is
    refused, named, and left as it was."""
    f = tmp_path / "lab.csv"
    lab_file(f)
    args = ["dataset", "import", str(f), "--columns", COLUMNS, "--units", UNITS,
            "--material", "glass", "--group", "g", "--pad-c", "34", "--room-c", "22",
            "--object-c", "24"]
    generated = tmp_path / "db"
    (generated / "pad").mkdir(parents=True)
    (generated / "pad" / "manifest.csv").write_text("x\n")
    (generated / "generation.json").write_text("{}")
    other = tmp_path / "notes"
    other.mkdir()
    (other / "keep.txt").write_text("mine")
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    for into, message in ((generated, rf"give {generated / 'pad'} to add to its pad"),
                          (other, r"it holds keep\.txt"),
                          (f, "a file, not a dataset folder")):
        assert main(args + ["--into", str(into)]) == 2
        err = " ".join(capsys.readouterr().err.split())
        assert f"--into {into}" in err and re.search(message, err), err
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before
    # An empty folder is taken, and the dataset then grows in place.
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(args + ["--into", str(empty)]) == 0
    assert len(load_dataset(empty)) == 1


def test_a_manifest_row_with_cells_past_its_header_or_no_file_is_named_by_line(tmp_path,
                                                                               capsys):
    # Cells past a row's end are blank (the columns are filled where known)
    # and a trailing empty cell is a spreadsheet's comma; a non-empty cell
    # past the header, or a row naming no file, is refused by line.
    lab = tmp_path / "lab"
    lab.mkdir()
    lab_file(lab / "a.csv")
    args = ["dataset", "import", "--columns", COLUMNS, "--units", UNITS, "--object-c", "24",
            "--pad-c", "34", "--room-c", "22", "--group", "g1"]
    for k, (rows, message) in enumerate((("a.csv,glass,g1,x\n", "line 2: 1 more cell(s)"),
                                         (",glass,g1\n", "line 2: no file named"))):
        (lab / "manifest.csv").write_text("file,material,group\n" + rows)
        assert main(args + ["--manifest", str(lab / "manifest.csv"),
                            "--into", str(tmp_path / f"bad{k}")]) == 2
        assert message in " ".join(capsys.readouterr().err.split())
        assert not (tmp_path / f"bad{k}").exists()
    for k, rows in enumerate(("a.csv,glass\n", "a.csv,glass,g1,\n")):
        (lab / "manifest.csv").write_text("file,material,group\n" + rows)
        assert main(args + ["--manifest", str(lab / "manifest.csv"),
                            "--into", str(tmp_path / f"ok{k}")]) == 0
        assert len(load_dataset(tmp_path / f"ok{k}")) == 1
