"""Model files are checked at load against docs/limits.md before anything
runs (issue 47): each of the probe's hostile files is refused with an error
naming the file and the field, and the 3 GB array is refused from its header
without being allocated."""

from __future__ import annotations

import io
import json
import math
import tracemalloc
import zipfile

import numpy as np
import pytest

from telethermal.errors import ModelFileError
from telethermal.ident.registry import load_model
from telethermal.npzfile import read_npz
from telethermal.physics.scene import load_scene, with_finger
from telethermal.render.generator import load_generator

SCENE = with_finger(load_scene("fingertip-7"))


@pytest.fixture(scope="module")
def files(trained_models):
    return trained_models.files(SCENE, 0)


def _members(path) -> dict:
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def _rewrite(src, dst, header_edit=None, array_edit=None):
    arrays = _members(src)
    header = json.loads(arrays["header"].tobytes())
    if header_edit:
        header_edit(header)
    if array_edit:
        array_edit(arrays)
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    with open(dst, "wb") as fh:
        np.savez(fh, **arrays)
    return dst


def _refused(load, path, *words):
    with pytest.raises(ModelFileError) as err:
        load(path)
    text = str(err.value)
    assert str(path) in text, text
    for word in words:
        assert word in text, text
    return text


def test_the_trained_files_load(files):
    assert load_model(files[0]).classes_ and load_generator(files[1]).materials


def test_a_header_declaring_a_3_gb_array_is_refused_without_allocating_it(files, tmp_path):
    # The probe's file: 3.2 MB on disk, an array header declaring 400 M
    # float64 (3.2 GB). Refused from the zip directory and the .npy header.
    path = tmp_path / "huge.npz"
    with zipfile.ZipFile(files[0]) as src, zipfile.ZipFile(path, "w") as out:
        for info in src.infolist():
            out.writestr(info, src.read(info))
        head = io.BytesIO()
        np.lib.format.write_array_header_1_0(
            head, {"descr": "<f8", "fortran_order": False, "shape": (400_000_000,)})
        out.writestr("w0.big.npy", head.getvalue() + b"\0" * 3_200_000)
    tracemalloc.start()
    try:
        text = _refused(load_model, path, "w0.big.npy", "3200000000 bytes", "holds 3200000")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2 * path.stat().st_size, (peak, text)      # nothing like 3.2 GB


@pytest.mark.parametrize("edit, words", [
    (lambda h: h.update(classes=[]), ["classes", "non-empty"]),
    (lambda h: h.update(classes=["wood", "x" * 300]), ["classes", "256 bytes"]),
    (lambda h: h.update(classes=["wood", "x" * 10_000]), ["classes[1]", "4096-byte"]),
    (lambda h: h.update(classes=["wood", "wood"]), ["twice"]),
    (lambda h: h["hyper"].update(threshold=math.nan), ["hyper.threshold", "nan"]),
    (lambda h: h["hyper"].update(threshold=2.0), ["hyper.threshold", "(0, 1]"]),
    (lambda h: h.update(sample_rate_hz=-1.0), ["sample_rate_hz"]),
    (lambda h: h.update(windows_s=[]), ["windows_s"]),
    (lambda h: h["learned"].update(prepare="x"), ["learned.prepare"]),
    (lambda h: h.update(scene="s" * 5000), ["header.scene", "4096"]),
])
def test_a_model_header_out_of_its_limits_is_refused(files, tmp_path, edit, words):
    path = _rewrite(files[0], tmp_path / "bad.npz", header_edit=edit)
    _refused(load_model, path, *words)


def test_nan_weights_are_refused_naming_the_array(files, tmp_path):
    def poison(arrays):
        name = sorted(k for k in arrays if k != "header")[-1]
        arrays[name] = arrays[name].copy()
        arrays[name].flat[0] = np.nan
    path = _rewrite(files[0], tmp_path / "nan.npz", array_edit=poison)
    _refused(load_model, path, "array", "finite")


def test_an_object_array_or_a_10_mb_header_is_refused(files, tmp_path):
    path = tmp_path / "text.npz"
    arrays = _members(files[0])
    with open(path, "wb") as fh:
        np.savez(fh, **arrays, names=np.array(["a", "b"]))
    _refused(load_model, path, "names.npy", "dtype")
    big = _rewrite(files[0], tmp_path / "big.npz",
                   header_edit=lambda h: h.update(note="y" * 10_000_000))
    _refused(load_model, big, "header.npy", "limit of a header")


@pytest.mark.parametrize("edit, words", [
    (lambda a: a.update({k: a[k] * np.nan for k in a if k.endswith(".w2")}), ["finite"]),
    (lambda a: a.update({k: a[k][:3] for k in a if k.endswith(".b1")}), ["cannot run"]),
])
def test_a_broken_generator_is_refused_at_load(files, tmp_path, edit, words):
    path = _rewrite(files[1], tmp_path / "gen.npz", array_edit=edit)
    _refused(load_generator, path, *words)


def test_a_generator_nan_scale_is_refused(files, tmp_path):
    def edit(h):
        h["scale"] = {k: math.nan for k in h["scale"]}
    path = _rewrite(files[1], tmp_path / "gen.npz", header_edit=edit)
    _refused(load_generator, path, "header.scale", "finite")


def test_the_slave_cli_exits_2_on_a_bad_model_and_writes_nothing(files, tmp_path, capsys):
    from telethermal.cli import main

    bad = _rewrite(files[0], tmp_path / "bad.npz", header_edit=lambda h: h.update(classes=[]))
    record = tmp_path / "rec"
    config = tmp_path / "slave.toml"
    config.write_text(f'[slave]\nscene = "fingertip-7"\nidentifier = "{bad}"\n'
                      f'generator = "{files[1]}"\nrecord_dir = "{record}"\n'
                      '[transport]\nsecurity = "plain"\ncontrol_port = 0\nstream_port = 0\n')
    assert main(["slave", "--config", str(config)]) == 2
    assert "classes" in capsys.readouterr().err
    assert not record.exists() or not any(record.iterdir())


def test_read_npz_names_a_truncated_file(files, tmp_path):
    data = files[0].read_bytes()
    cut = tmp_path / "cut.npz"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(ModelFileError, match="cut.npz"):
        read_npz(cut, "telethermal-identifier", 99, "model")
