"""Every file reader the product has, fed hostile bytes (issue 47): a real
file with bytes flipped, cut, inserted or duplicated, and made-up content.
Each load either succeeds or raises the reader's own error naming the file:
never another exception. The peak memory of each load (tracemalloc) is
kept beside the file's size (``PEAKS``, printed with the tally)."""

from __future__ import annotations

import tracemalloc
from importlib import resources

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fuzzing import TALLY, fuzz_settings, keep_peak
from telethermal.data.csv_import import CsvSpec, read_lab_csv
from telethermal.errors import CalibrationError, DatasetError, ModelFileError, SceneError
from telethermal.ident.registry import load_model
from telethermal.physics.scene import load_scene, with_finger
from telethermal.record.recording import Recorder, RecordingError, read_recording
from telethermal.render.generator import load_generator

SCENE = with_finger(load_scene("fingertip-7"))
#: A load's peak memory (tracemalloc) may be 20 times its file's size, or
#: this much whatever the file (docs/limits.md): a reader's fixed cost.
MEMORY_FLOOR_BYTES = 1024 * 1024


def mutations(data: bytes):
    """``data`` with up to 4 edits: a byte flipped, set, cut, a run inserted
    or duplicated."""
    n = len(data)
    edit = st.one_of(
        st.tuples(st.just("flip"), st.integers(0, n - 1), st.integers(1, 255)),
        st.tuples(st.just("set"), st.integers(0, n - 1), st.integers(0, 255)),
        st.tuples(st.just("cut"), st.integers(0, n), st.just(0)),
        st.tuples(st.just("insert"), st.integers(0, n), st.binary(min_size=1, max_size=64)),
        st.tuples(st.just("repeat"), st.integers(0, n - 1), st.integers(1, 4096)))

    def apply(edits):
        out = bytearray(data)
        for kind, at, arg in edits:
            at = min(at, len(out) - 1) if kind in ("flip", "set", "repeat") else \
                min(at, len(out))
            if not out:
                break
            if kind == "flip":
                out[at] ^= arg
            elif kind == "set":
                out[at] = arg
            elif kind == "cut":
                del out[at:]
            elif kind == "insert":
                out[at:at] = arg
            else:
                out[at:at] = out[at:at + arg]
        return bytes(out)
    return st.lists(edit, min_size=1, max_size=4).map(apply)


def _load(reader: str, load, path, errors) -> None:
    """One load: ``errors`` or success; tallied, its peak memory kept."""
    size = max(path.stat().st_size, 1)
    tracemalloc.start()
    try:
        load(path)
        TALLY[reader]["loaded"] += 1
    except errors as exc:
        assert str(path) in str(exc) or path.name in str(exc), (reader, str(exc)[:200])
        TALLY[reader]["refused"] += 1
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    keep_peak(reader, peak, size)
    assert peak <= max(20 * size, MEMORY_FLOOR_BYTES), (reader, peak, size)


@pytest.fixture(scope="module")
def model_files(trained_models):
    return [p.read_bytes() for p in trained_models.files(SCENE, 0)]


@pytest.fixture(scope="module")
def recording_bytes(tmp_path_factory):
    path = tmp_path_factory.mktemp("rec") / "r.mcap"
    rec = Recorder(path, "slave", {"scene": "fingertip-7"}, {"identifier.npz": b"x" * 64})
    for c in range(5):
        for i in range(8):
            rec.log("/slave/sample_batch", c * 0.1 + i * 1e-3,
                    {"contact_id": c, "k0": i * 4, "t_s": [0.001 * k for k in range(4)],
                     "heat_flux_W_m2": [1.0, 2.0, 3.0, 4.0], "object_ir_c": 22.0,
                     "gap_k": 10.0, "pad_before_c": 33.0, "object_true_c": 22.0})
        rec.sync()
    rec.close()
    return path.read_bytes()


@fuzz_settings(scale=0.5)
@given(data=st.data())
def test_identifier_files(model_files, tmp_path_factory, data):
    path = tmp_path_factory.mktemp("m") / "identifier.npz"
    path.write_bytes(data.draw(mutations(model_files[0])))
    _load("identifier", load_model, path, ModelFileError)


@fuzz_settings(scale=0.5)
@given(data=st.data())
def test_generator_files(model_files, tmp_path_factory, data):
    path = tmp_path_factory.mktemp("g") / "generator.npz"
    path.write_bytes(data.draw(mutations(model_files[1])))
    _load("generator", load_generator, path, ModelFileError)


@fuzz_settings()
@given(data=st.data())
def test_recordings(recording_bytes, tmp_path_factory, data):
    path = tmp_path_factory.mktemp("r") / "rec.mcap"
    path.write_bytes(data.draw(mutations(recording_bytes)))
    _load("recording", read_recording, path, RecordingError)


def _scene_text() -> bytes:
    return resources.files("telethermal").joinpath("scenes", "fingertip-7.toml").read_bytes()


@fuzz_settings()
@given(data=st.data())
def test_scene_files(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("s") / "scene.toml"
    text = data.draw(st.one_of(mutations(_scene_text()), st.text(max_size=400).map(str.encode)))
    path.write_bytes(text)
    _load("scene", load_scene, path, SceneError)


def _csv_text() -> bytes:
    t = np.arange(60) / 100.0
    rows = ["t_s,heat_flux_W_m2,temperature_C,force_N"] + [
        f"{x:.3f},{-1000 * (x > 0.2):.1f},{34 - 2 * (x > 0.2):.2f},{10.0 * (x > 0.2):.1f}"
        for x in t]
    return ("\n".join(rows) + "\n").encode()


@fuzz_settings()
@given(data=st.data())
def test_lab_csv_files(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("c") / "lab.csv"
    path.write_bytes(data.draw(st.one_of(mutations(_csv_text()),
                                         st.text(max_size=400).map(str.encode))))
    _load("csv", lambda p: read_lab_csv(p, CsvSpec({}, {})), path, DatasetError)


def _calibration_text() -> bytes:
    from telethermal.ident.pad_calibration import (CalibratedParameter, PadCalibration,
                                                   pad_digest)
    return PadCalibration(
        SCENE.name, pad_digest(SCENE),
        (CalibratedParameter(("flux_gain",), "flux sensor gain", 1.02, 1.0, 1.04),
         CalibratedParameter(("flux_lag_s",), "flux sensor lag", 1.1, 1.0, 1.2),
         CalibratedParameter(("layers[0].resistance", "layers[1].resistance"),
                             "resistances", 0.9, 0.8, 1.0)),
        ("alumina heat capacity",), 3000.0, 1.02, 0.01, 0.03, 6,
        ("steel", "wood"), design_sd=0.2,
        prior_fitted=(CalibratedParameter(("layers[2].heat_capacity",), "alumina heat capacity",
                                          1.05, 0.7, 1.5),)).to_toml().encode()


def _load_calibration(path):
    """Read and checked against the scene, as a service takes it."""
    from telethermal.ident.pad_calibration import pad_calibration
    pad_calibration(str(path), SCENE)


@fuzz_settings()
@given(data=st.data())
def test_calibration_files(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("k") / "cal.toml"
    path.write_bytes(data.draw(st.one_of(mutations(_calibration_text()),
                                         st.text(max_size=400).map(str.encode))))
    _load("calibration", _load_calibration, path, CalibrationError)
