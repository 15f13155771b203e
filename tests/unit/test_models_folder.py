"""``telethermal models`` (teleop.models.write_models) leaves nothing behind
when it fails: the folder it made for the models and the parents it made
for that folder go again; what was there before stays."""

from __future__ import annotations

import pytest

from telethermal.teleop.models import write_models


def test_a_failed_run_removes_the_folders_it_made_and_only_those(tmp_path):
    kept = tmp_path / "lab"
    kept.mkdir()
    (kept / "notes.txt").write_text("the lab's own file\n")
    out = kept / "a" / "b" / "models"
    with pytest.raises(Exception, match="no-such-calibration.toml"):
        write_models(out, "fingertip-7", calibration=str(tmp_path / "no-such-calibration.toml"))
    assert not (kept / "a").exists()                       # models, b and a: made, removed
    assert (kept / "notes.txt").read_text() == "the lab's own file\n"


def test_a_parent_that_gained_a_file_meanwhile_is_kept(tmp_path, monkeypatch):
    import telethermal.teleop.models as models

    out = tmp_path / "a" / "models"

    def fails_after_a_file_appears(*args, **kwargs):
        (tmp_path / "a" / "other.txt").write_text("someone else's\n")
        raise RuntimeError("training failed")

    monkeypatch.setattr(models, "_write_models", fails_after_a_file_appears)
    with pytest.raises(RuntimeError, match="training failed"):
        write_models(out, "fingertip-7")
    assert not out.exists() and (tmp_path / "a" / "other.txt").exists()
