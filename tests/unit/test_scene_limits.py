"""Scene files are checked at load against docs/limits.md (issue 47): bad
UTF-8, 10,000-deep nested arrays, huge dotted keys, sensor values beyond
their upper bounds, names over the wire's 256 bytes, too many objects: each
a SceneError naming the file (and the key), never a traceback."""

from __future__ import annotations

import tracemalloc

import pytest

from telethermal.errors import SceneError
from telethermal.physics import scenefile
from telethermal.physics.scene import load_scene

SHIPPED = "fingertip-7"


def _text() -> str:
    from importlib import resources
    return resources.files("telethermal").joinpath("scenes", f"{SHIPPED}.toml").read_text()


def _scene_file(tmp_path, text: str | bytes):
    path = tmp_path / "s.toml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    return path


def _refused(path, *words) -> str:
    with pytest.raises(SceneError) as err:
        load_scene(path)
    text = str(err.value)
    assert str(path) in text, text
    for word in words:
        assert word in text, text
    return text


def test_the_shipped_scene_loads_from_a_file(tmp_path):
    assert load_scene(_scene_file(tmp_path, _text())).name == SHIPPED


def test_bad_utf8_is_named_with_its_byte(tmp_path):
    data = _text().encode()
    _refused(_scene_file(tmp_path, data[:40] + b"\xff\xfe" + data[40:]), "UTF-8", "byte 40")


def test_10000_deep_nested_arrays_are_refused(tmp_path):
    _refused(_scene_file(tmp_path, _text() + "\ndeep = " + "[" * 10_000 + "]" * 10_000 + "\n"),
             "nested too deep")


def test_a_huge_dotted_key_is_refused_before_tomllib(tmp_path):
    # The probe's 40 KB file took tomllib 1.58 GB: refused from the text.
    path = _scene_file(tmp_path, _text() + "\n" + ".".join(["a"] * 20_000) + " = 1\n")
    tracemalloc.start()
    try:
        _refused(path, "line", "dotted parts")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20 * path.stat().st_size, peak


def test_a_file_over_the_size_limit_is_refused_unread(tmp_path, monkeypatch):
    monkeypatch.setattr(scenefile, "MAX_SCENE_BYTES", 1000)
    _refused(_scene_file(tmp_path, _text() + "#" * 2000 + "\n"), "over the 1000-byte limit")


@pytest.mark.parametrize("key, value, words", [
    ("object_readings", "1e9", ["object_readings", "10000"]),
    ("object_readings", "1e308", ["object_readings"]),
    ("instrument_seed", "inf", ["instrument_seed", "finite"]),
    ("instrument_seed", "nan", ["instrument_seed", "finite"]),
    ("flux_lag_s", "1e6", ["flux_lag_s"]),
])
def test_sensor_values_beyond_their_upper_bounds_are_refused(tmp_path, key, value, words):
    head, sensors = _text().split("[sensors]\n", 1)
    lines = [ln for ln in sensors.split("\n") if not ln.startswith(f"{key} ")]
    text = head + "[sensors]\n" + f"{key} = {value}\n" + "\n".join(lines)
    _refused(_scene_file(tmp_path, text), "[sensors]", *words)


def test_a_name_over_256_bytes_is_refused(tmp_path):
    text = _text().replace(f'name = "{SHIPPED}"', f'name = "{"é" * 200}"', 1)
    _refused(_scene_file(tmp_path, text), "'name'", "400 bytes", "256-byte limit")


def test_too_many_objects_are_refused_before_any_is_modelled(tmp_path):
    block = _text()[_text().index("[[objects]]"):]
    first = block[:block.index("[[objects]]", 1)] if "[[objects]]" in block[1:] else block
    _refused(_scene_file(tmp_path, _text() + "\n" + first * 300), "[[objects]]", "limit of 256")
