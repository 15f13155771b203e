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
