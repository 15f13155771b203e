"""Where a user following the docs stumbled (the docs review of issue 46):
each case as a user meets it, through the command line, in process."""

import csv
from importlib import resources

import numpy as np
import pytest

from telethermal.cli import main
from telethermal.data.dataset import load_dataset
from telethermal.physics.scene import load_scene
from telethermal.record.recording import Recorder


def _tiny_text() -> str:
    """A lab's copy of the shipped scene (docs/scenes.md: its own name), in
    a room of 21.5 C, with few touches."""
    text = resources.files("telethermal").joinpath("scenes", "fingertip-7.toml").read_text()
    for old, new in (('name = "fingertip-7"', 'name = "tiny"'),
                     ("room_temp_c = 24.0", "room_temp_c = 21.5"),
                     ("trials_per_material = 10", "trials_per_material = 3"),
                     ("persons = 5", "persons = 1"), ("trials_per_person = 10",
                                                      "trials_per_person = 1")):
        assert old in text, old
        text = text.replace(old, new)
    return text


@pytest.fixture
def tiny(tmp_path):
    """A lab's own scene file (docs/scenes.md: its own name, a room of 21.5 C)."""
    path = tmp_path / "tiny.toml"
    path.write_text(_tiny_text())
    return path


def test_scenes_shows_a_scene_file_given_by_path(tiny, capsys):
    """docs/scenes.md: every command that takes --scene takes a path;
    `telethermal scenes` took none (unrecognized arguments)."""
    assert main(["scenes", "--scene", str(tiny), "--scene", "fingertip-7", "-v"]) == 0
    out = capsys.readouterr().out
    assert "tiny" in out and "plexiglass" in out and "fingertip-7" in out
    assert "gripper-case-V" not in out                  # only the scenes asked for
    assert main(["scenes", "--scene", str(tiny.with_name("tiny2.toml"))]) == 2
    assert "tiny2.toml does not exist" in capsys.readouterr().err


def write_recording(path, scene_name, material="plexiglass"):
    """A session's recording as `session --scene FILE --record` writes it: the
    scene by its name (not its file), one slave contact."""
    t = np.round(np.arange(-0.1, 0.5, 0.01), 6)
    flux = np.where(t < 0, 0.0, 2000.0 / np.sqrt(np.maximum(t, 0.01)))
    rec = Recorder(path, "session", {"scene": scene_name, "material": material})
    rec.log("/slave/samples", 0.0, {
        "t_s": t.tolist(), "heat_flux_W_m2": flux.tolist(),
        "temperature_C": (33.0 - 0.01 * flux ** 0.5).tolist(),
        "force_N": np.where(t < 0, 0.0, 8.0).tolist(), "contact_id": 0,
        "samples": len(t), "object_ir_c": 23.9, "pad_before_c": 33.9})
    rec.close()
    return path


def room_c(folder):
    with (folder / "manifest.csv").open() as fh:
        return [float(row["T_room_C"]) for row in csv.DictReader(fh)]


def test_a_recording_made_on_a_scene_file_is_imported(tiny, tmp_path, capsys):
    """docs/own-pad.md, step 2: `dataset import FILE.mcap --into DIR ...` of
    a recording made on a scene file failed (`unknown scene 'tiny'`: the
    room's temperature was looked up among the shipped scenes). Now: the
    error says what to give; with --scene FILE the scene's room (21.5 C);
    with --room-c that; a shipped scene's recording needs neither."""
    rec = write_recording(tmp_path / "touch.mcap", "tiny")
    args = ["dataset", "import", str(rec), "--material", "plexiglass", "--group", "day-1"]
    assert main(args + ["--into", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert "'tiny' is not a shipped one" in err and "--scene FILE" in err and "--room-c" in err
    assert not (tmp_path / "a").exists()
    assert main(args + ["--into", str(tmp_path / "a"), "--scene", str(tiny)]) == 0
    assert room_c(tmp_path / "a") == [21.5]
    assert load_dataset(tmp_path / "a")[0].group == "day-1"
    assert main(args + ["--into", str(tmp_path / "b"), "--room-c", "22.25"]) == 0
    assert room_c(tmp_path / "b") == [22.25]
    assert main(args + ["--into", str(tmp_path / "c"), "--scene", "fingertip-7"]) == 2
    assert "recorded on scene 'tiny', but --scene is 'fingertip-7'" in capsys.readouterr().err
    shipped = write_recording(tmp_path / "shipped.mcap", "fingertip-7")
    assert main(["dataset", "import", str(shipped), "--into", str(tmp_path / "d")]) == 0
    assert room_c(tmp_path / "d") == [load_scene("fingertip-7").room_temp_c]


def test_a_generated_datasets_manifest_is_imported_and_mixed_with_lab_contacts(
        tiny, tmp_path, capsys):
    """`dataset import --manifest` refused the manifest `dataset generate`
    writes (unknown columns trial_id, sample_rate_hz, ...). Now its trials
    are added as they are (ids, labels, temperatures, channels, extra
    columns), and a recorded contact added after them (other extra columns)
    reads back; options that only a lab's files take are refused."""
    db = tmp_path / "standin"
    assert main(["dataset", "generate", "--scene", str(tiny), "--out", str(db)]) == 0
    merged = tmp_path / "merged"
    manifest = str(db / "pad" / "manifest.csv")
    assert main(["dataset", "import", "--manifest", manifest, "--into", str(merged)]) == 0
    source, got = load_dataset(db / "pad"), load_dataset(merged)
    assert [t.trial_id for t in got] == [t.trial_id for t in source]
    for a, b in zip(source, got):
        assert (a.material, a.group, a.T_object_C, a.T_pad_C, a.T_room_C, a.extra) == \
            (b.material, b.group, b.T_object_C, b.T_pad_C, b.T_room_C, b.extra)
        for name, values in a.channels.items():
            np.testing.assert_array_equal(values, b.channels[name])
    rec = write_recording(tmp_path / "touch.mcap", "tiny", "wood")
    assert main(["dataset", "import", str(rec), "--into", str(merged), "--scene", str(tiny),
                 "--group", "day-1"]) == 0
    assert len(load_dataset(merged)) == len(source) + 1
    assert main(["dataset", "validate", str(merged)]) == 0
    assert main(["dataset", "import", "--manifest", manifest, "--into", str(merged)]) == 2
    assert "imported before" in capsys.readouterr().err
    assert main(["dataset", "import", "--manifest", manifest, "--into", str(tmp_path / "x"),
                 "--group", "g"]) == 2
    assert "not --group" in capsys.readouterr().err and not (tmp_path / "x").exists()


def test_a_recording_made_on_a_scene_file_replays_with_its_scene(tiny, tmp_path, capsys,
                                                                 trained_models, monkeypatch):
    """`telethermal replay` of a recording made on a scene file failed: the
    default identifier needs its pad's scene, found by the recorded name,
    and the error said "give the scene file: --scene FILE", an option replay
    did not have. Now replay takes --scene FILE (a file of another name is
    refused) and replays the touch sample for sample."""
    import telethermal.physics.scene as scene_module
    from telethermal.teleop.display_config import DisplayConfig
    from telethermal.sim.inprocess import run_session
    from telethermal.physics.scene import with_finger

    scene = with_finger(load_scene(tiny))
    rec = tmp_path / "touch.mcap"
    run_session(scene, "plexiglass", *trained_models.pair(scene, 0),
                DisplayConfig(feedforward_model="static", idle="object"), contact_s=0.4,
                seed=1, record=rec)
    monkeypatch.setattr(scene_module, "_FILES_BY_NAME", {})   # a new process: none loaded
    assert main(["replay", str(rec), "--out", str(tmp_path / "a")]) == 2
    assert "--scene FILE" in capsys.readouterr().err
    assert main(["replay", str(rec), "--out", str(tmp_path / "b"), "--scene", "fingertip-7"]) == 2
    assert "recorded on scene 'tiny', but --scene is 'fingertip-7'" in capsys.readouterr().err
    assert main(["replay", str(rec), "--out", str(tmp_path / "c"), "--scene", str(tiny)]) == 0
    assert "identical to the recording, sample for sample" in capsys.readouterr().out
