"""Every TOML file the product reads (service configs, calibration files,
fault profiles: ``tomltables.read_toml``) is held to the scene file's
limits (issue 47): size, UTF-8, dotted keys, nesting; each a clear error
naming the file, never a traceback."""

from __future__ import annotations

import tomllib

import pytest
from hypothesis import given
from hypothesis import strategies as st

from telethermal.devices.board import Calibration, DeviceError
from telethermal.tomltables import MAX_TOML_BYTES, read_toml


@pytest.mark.parametrize("content, words", [
    (b"[force]\nscale = 1.0\n\xff\n", ["not UTF-8", "byte 20"]),
    (b"x = " + b"[" * 10_000 + b"]" * 10_000 + b"\n", ["nested too deep"]),
    (".".join(["a"] * 5000).encode() + b" = 1\n", ["line 1", "5000 dotted parts"]),
    (b"#" * (MAX_TOML_BYTES + 1), ["over the 1048576-byte limit"]),
    (b"[force\nscale = 1\n", ["not valid TOML"]),
])
def test_a_calibration_file_out_of_the_limits_is_a_clear_error(tmp_path, content, words):
    path = tmp_path / "cal.toml"
    path.write_bytes(content)
    with pytest.raises(DeviceError) as err:
        Calibration.load(path)
    for word in [str(path), *words]:
        assert word in str(err.value), str(err.value)[:300]


def test_a_good_file_reads(tmp_path):
    path = tmp_path / "cal.toml"
    path.write_text("[force]\nscale = 1.5\n")
    assert read_toml(path, "calibration file") == {"force": {"scale": 1.5}}
    assert Calibration.load(path).force_scale == 1.5


@given(st.text())
def test_toml_str_reads_back_as_the_text(text):
    """Any text, quotes, backslashes, control characters, DEL and astral
    characters included, written as a TOML string reads back unchanged."""
    from telethermal.tomltables import toml_str

    assert tomllib.loads(f"k = {toml_str(text)}\n")["k"] == text
