"""The one size check every reader uses (filelimits): the file, its size and
the limit named; a file that cannot be read named; text that is not UTF-8
named with its first bad byte."""

import pytest

from telethermal.errors import SceneError
from telethermal.filelimits import check_size, read_text


def test_a_file_over_its_limit_is_named_with_both_sizes(tmp_path):
    path = tmp_path / "big.toml"
    path.write_bytes(b"x" * 101)
    assert check_size(path, 101, "scene file", SceneError) == 101
    with pytest.raises(SceneError, match=r"big.toml: 101 bytes, over the 100-byte limit of a "
                                         r"scene file \(docs/limits.md\)"):
        check_size(path, 100, "scene file", SceneError)


def test_a_missing_file_and_bad_utf8_are_named(tmp_path):
    with pytest.raises(SceneError, match="gone.toml: cannot read"):
        read_text(tmp_path / "gone.toml", 100, "scene file", SceneError)
    path = tmp_path / "bad.toml"
    path.write_bytes(b"ok = 1\n\xff")
    with pytest.raises(SceneError, match=r"bad.toml: not UTF-8 text \(byte 7: b'\\xff'\)"):
        read_text(path, 100, "scene file", SceneError)
    path.write_bytes("name = \"é\"\n".encode())
    assert read_text(path, 100, "scene file", SceneError) == "name = \"é\"\n"


def test_a_fifo_is_refused_not_read_without_end(tmp_path):
    """A FIFO (or a device) reports size 0: it is refused as not a regular
    file, before any read (which would wait for a writer)."""
    import os

    fifo = tmp_path / "scene.toml"
    os.mkfifo(fifo)
    with pytest.raises(SceneError, match="scene.toml: not a regular file"):
        read_text(fifo, 100, "scene file", SceneError)


def test_a_file_that_grows_past_its_checked_size_is_refused(tmp_path, monkeypatch):
    """The size is read, then the file: never more than the limit is read,
    even when the file grew in between."""
    from pathlib import Path

    from telethermal import filelimits

    path = tmp_path / "r.mcap"
    path.write_bytes(b"x" * 50)
    checked = filelimits.check_size

    def grows(*a):
        size = checked(*a)
        path.write_bytes(b"x" * 500)
        return size
    monkeypatch.setattr(filelimits, "check_size", grows)
    with pytest.raises(SceneError, match="over the 100-byte limit .* grew while being read"):
        filelimits.read_bytes(Path(path), 100, "recording", SceneError)
