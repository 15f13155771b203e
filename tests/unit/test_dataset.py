"""The dataset format: round trips, and clear errors that leave nothing half-written."""

import csv

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from telethermal.data.dataset import (MANIFEST_COLUMNS, Trial, load_dataset, read_manifest,
                                      read_trial_file, write_dataset)
from telethermal.errors import DatasetError


def make_trial(i=0, rate=100.0, n=50, material="wood"):
    t = (np.arange(n) - 10) / rate
    return Trial(trial_id=f"{material}-{i}", material=material, file=f"trials/{material}-{i}.csv",
                 sample_rate_hz=rate, T_object_C=24.0, T_pad_C=34.0, T_room_C=24.0,
                 group=f"trial-{i}", extra={"note": "x"},
                 channels={"t_s": t, "heat_flux_W_m2": np.sin(t) * 1000.0,
                           "temperature_C": 30.0 + t})


def written(tmp_path, trials=None):
    root = tmp_path / "ds"
    write_dataset(root, trials or [make_trial(0), make_trial(1)])
    return root


def test_round_trip(tmp_path):
    root = written(tmp_path)
    trials = load_dataset(root)
    assert [t.trial_id for t in trials] == ["wood-0", "wood-1"]
    assert trials[0].extra == {"note": "x"} and trials[0].gap_k == 10.0
    np.testing.assert_allclose(trials[0].channels["heat_flux_W_m2"],
                               make_trial().channels["heat_flux_W_m2"], atol=5e-4)


def edit_manifest(root, row, column, value):
    path = root / "manifest.csv"
    with path.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    rows[row][column] = value
    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def test_missing_trial_file_names_file_and_row(tmp_path):
    root = written(tmp_path)
    (root / "trials" / "wood-1.csv").unlink()
    with pytest.raises(DatasetError) as info:
        read_manifest(root)
    assert "row 3" in str(info.value) and "wood-1.csv" in str(info.value)


def test_non_numeric_manifest_cell_names_row_and_column(tmp_path):
    root = written(tmp_path)
    edit_manifest(root, 0, "T_object_C", "warm")
    with pytest.raises(DatasetError, match=r"row 2, column 'T_object_C': 'warm'"):
        read_manifest(root)


def test_non_numeric_trial_cell_names_file_line_and_column(tmp_path):
    root = written(tmp_path)
    path = root / "trials" / "wood-0.csv"
    lines = path.read_text().splitlines()
    cells = lines[5].split(",")
    cells[2] = "n/a"
    lines[5] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError) as info:
        load_dataset(root)
    message = str(info.value)
    assert "wood-0.csv line 6" in message and "'temperature_C'" in message and "n/a" in message


def test_sample_rate_disagreeing_with_t_s_is_refused(tmp_path):
    root = written(tmp_path)
    edit_manifest(root, 1, "sample_rate_hz", "1000")
    with pytest.raises(DatasetError) as info:
        load_dataset(root)
    assert "wood-1.csv" in str(info.value) and "sample_rate_hz = 1000" in str(info.value)


def test_missing_manifest_column_is_named(tmp_path):
    root = written(tmp_path)
    text = (root / "manifest.csv").read_text().replace("group", "grp", 1)
    (root / "manifest.csv").write_text(text)
    with pytest.raises(DatasetError, match="missing column.*group"):
        read_manifest(root)


def test_a_manifest_that_is_not_utf8_text_is_named_not_a_traceback(tmp_path):
    # A binary file saved as manifest.csv (an export gone wrong): named as
    # such by every reader of a dataset, and by the import's manifest check.
    from telethermal.data.dataset import is_dataset_manifest

    root = written(tmp_path)
    (root / "manifest.csv").write_bytes(b"trial_id,material\n\xff\xfe\x00garbage\n")
    with pytest.raises(DatasetError, match=r"manifest.csv: not UTF-8 text \(byte 18\)"):
        load_dataset(root)
    (root / "manifest.csv").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(DatasetError, match=r"manifest.csv: not UTF-8 text \(byte 0\)"):
        is_dataset_manifest(root / "manifest.csv")


def test_t_s_must_increase(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text("t_s,heat_flux_W_m2\n0.0,1\n0.01,2\n0.01,3\n")
    with pytest.raises(DatasetError, match="does not increase"):
        read_trial_file(path)


def test_extra_channels_and_missing_channels_are_allowed(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text("t_s,humidity_pct\n0.0,40\n0.01,41\n")
    assert set(read_trial_file(path, 100.0)) == {"t_s", "humidity_pct"}


def test_failed_write_leaves_nothing_half_written(tmp_path):
    bad = make_trial(1)
    bad.channels["heat_flux_W_m2"][3] = np.nan
    with pytest.raises(DatasetError, match="not finite"):
        write_dataset(tmp_path / "ds", [make_trial(0), bad])
    assert list(tmp_path.iterdir()) == []  # no ds, no staging folder


def test_existing_dataset_is_kept_unless_overwrite(tmp_path):
    root = written(tmp_path)
    before = (root / "manifest.csv").read_text()
    with pytest.raises(DatasetError, match="not empty"):
        write_dataset(root, [make_trial(7)])
    assert (root / "manifest.csv").read_text() == before
    write_dataset(root, [make_trial(7)], overwrite=True)
    assert [t.trial_id for t in read_manifest(root)] == ["wood-7"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]


def test_overwrite_replaces_a_dataset_and_nothing_else(tmp_path):
    # --force on a mistyped --out: a file, or a folder of other things, is
    # not a dataset to replace; each is refused and left as it was.
    afile = tmp_path / "notes.bin"
    afile.write_bytes(b"mine")
    folder = tmp_path / "home"
    folder.mkdir()
    (folder / "keep.txt").write_text("mine")
    with pytest.raises(DatasetError, match="a file, not a dataset folder"):
        write_dataset(afile, [make_trial(1)], overwrite=True)
    with pytest.raises(DatasetError, match="not a dataset .no dataset's manifest.csv or generation.json"):
        write_dataset(folder, [make_trial(1)], overwrite=True)
    assert afile.read_bytes() == b"mine" and (folder / "keep.txt").read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["home", "notes.bin"]
    # A lab's raw folder has a manifest.csv too (its list of files): not a dataset.
    lab = tmp_path / "lab"
    lab.mkdir()
    (lab / "manifest.csv").write_text("file,material\na0.csv,wood\n")
    (lab / "a0.csv").write_text("time_ms,q\n0,1\n")
    with pytest.raises(DatasetError, match="a lab's own manifest.csv is not one"):
        write_dataset(lab, [make_trial(1)], overwrite=True)
    assert sorted(p.name for p in lab.iterdir()) == ["a0.csv", "manifest.csv"]


finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False)


@settings(max_examples=40, deadline=None)
@given(st.integers(min_value=2, max_value=40), st.sampled_from([10.0, 100.0, 1000.0]),
       st.lists(finite, min_size=40, max_size=40))
def test_any_numeric_trial_round_trips(tmp_path_factory, n, rate, values):
    root = tmp_path_factory.mktemp("h") / "ds"
    trial = make_trial(0, rate=rate, n=n)
    trial.channels["heat_flux_W_m2"] = np.array(values[:n])
    write_dataset(root, [trial])
    back = load_dataset(root)[0].channels
    np.testing.assert_allclose(back["heat_flux_W_m2"], values[:n], atol=5e-4)
    np.testing.assert_allclose(back["t_s"], trial.channels["t_s"], atol=5e-10)


@settings(max_examples=60, deadline=None)
@given(st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=30))
def test_garbage_cells_give_dataset_errors_not_crashes(tmp_path_factory, cell):
    path = tmp_path_factory.mktemp("g") / "x.csv"
    path.write_text(f"t_s,heat_flux_W_m2\n0.0,1\n0.01,{cell}\n".replace("\r", ""))
    try:
        read_trial_file(path)
    except DatasetError:
        pass


def test_manifest_columns_are_the_documented_ones():
    assert MANIFEST_COLUMNS == ("trial_id", "material", "file", "sample_rate_hz", "T_object_C",
                                "T_pad_C", "T_room_C", "group")


def test_a_trials_digest_follows_its_content_not_its_name(tmp_path):
    from telethermal.data.dataset import trial_digest

    a = load_dataset(written(tmp_path))
    renamed = make_trial(0)
    renamed.trial_id, renamed.file = "copy", "elsewhere/copy.csv"
    b = load_dataset(written(tmp_path / "other", [renamed, make_trial(2, n=60)]))
    assert trial_digest(a[0]) == trial_digest(b[0])           # the same contact, copied
    # (make_trial's two trials hold the same samples: one content, one digest)
    assert trial_digest(a[1]) == trial_digest(a[0]) != trial_digest(b[1])
