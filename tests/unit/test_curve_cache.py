"""The effusivity estimator's curves on disk (ident/curvecache.py): read
back, they give the very estimates the built ones give; a corrupt file is
rebuilt; another key misses; a folder that cannot be written leaves the
curves in memory. Small grids (6 x 4 nodes, 0.1 s) keep each build cheap."""

import dataclasses
import logging

import numpy as np
import pytest

from telethermal.cachedir import CACHE_ENV
from telethermal.data.generate import pad_database
from telethermal.ident import curvecache
from telethermal.ident.effusivity import EffusivityEstimator
from telethermal.ident.prepare import from_trials
from telethermal.physics.scene import load_scene

SCENE = load_scene("fingertip-7")
SMALL = {"max_s": 0.1, "n_e": 6, "n_h": 4, "n_prior": 200, "n_sessions": 4}


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A fresh cache folder, and a count of the curves built (not read)."""
    folder = tmp_path / "cache"
    monkeypatch.setenv(CACHE_ENV, str(folder))
    built = []
    real = curvecache.effusivity_family

    def counting(*args, **kw):
        built.append(args[1])                     # the object temperature
        return real(*args, **kw)

    monkeypatch.setattr(curvecache, "effusivity_family", counting)
    return folder, built


def _estimator(scene=SCENE, **kw):
    return EffusivityEstimator.for_scene(scene, family=curvecache.cached_family, **{**SMALL, **kw})


def _touch():
    contacts = from_trials(list(pad_database(SCENE, np.random.default_rng(3))), max_s=0.1)[0]
    return contacts.x[0, :101, 0], float(contacts.gap_k[0])


def test_curves_read_back_give_the_same_estimates(cache):
    folder, built = cache
    first = _estimator()
    assert len(built) == 1 and len(list(folder.glob("curves-*.npz"))) == 1
    again = _estimator()
    assert len(built) == 1                                # read, not built
    for name in ("log_e", "u", "t_s", "g"):
        assert np.array_equal(getattr(first.family, name), getattr(again.family, name))
    x, gap_k = _touch()
    # The same arrays make the same spline: the same estimate, bit for bit.
    assert first.estimate(x, gap_k) == again.estimate(x, gap_k)


@pytest.mark.parametrize("damage", [b"not an npz", b"PK\x03\x04 truncated"])
def test_a_corrupt_cache_file_is_rebuilt_and_logged(cache, caplog, damage):
    folder, built = cache
    _estimator()
    (path,) = folder.glob("curves-*.npz")
    path.write_bytes(damage)
    with caplog.at_level(logging.WARNING, logger="telethermal.ident.curvecache"):
        rebuilt = _estimator()
    assert len(built) == 2
    assert any(str(path) in r.getMessage() and "rebuilding" in r.getMessage()
               for r in caplog.records)
    # ... and written again: the next process reads it.
    assert np.array_equal(_estimator().family.g, rebuilt.family.g) and len(built) == 2


def test_a_file_holding_other_curves_is_not_taken_for_these(cache, caplog):
    """A file renamed over another key's name: its header's key differs."""
    folder, built = cache
    _estimator()
    (path,) = folder.glob("curves-*.npz")
    _estimator(object_temp_c=SCENE.objects[0].temp_c + 5.0)
    other = next(p for p in folder.glob("curves-*.npz") if p != path)
    path.write_bytes(other.read_bytes())
    with caplog.at_level(logging.WARNING, logger="telethermal.ident.curvecache"):
        _estimator()
    assert len(built) == 3 and "holds curves of key" in caplog.text


def test_another_object_temperature_or_pad_misses(cache):
    folder, built = cache
    temp_c = SCENE.objects[0].temp_c
    _estimator()
    _estimator(object_temp_c=temp_c + 5.0)
    thicker = dataclasses.replace(SCENE.pad.layers[0], thickness_m=2 * SCENE.pad.layers[0].thickness_m)
    other_pad = dataclasses.replace(SCENE, pad=dataclasses.replace(
        SCENE.pad, layers=(thicker,) + SCENE.pad.layers[1:]))
    _estimator(other_pad)
    assert built == [temp_c, temp_c + 5.0, temp_c]
    assert len(list(folder.glob("curves-*.npz"))) == 3


def test_a_cache_that_cannot_be_written_leaves_the_curves_in_memory(tmp_path, monkeypatch,
                                                                     caplog):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    monkeypatch.setenv(CACHE_ENV, str(blocker / "cache"))     # under a file: never a folder
    with caplog.at_level(logging.WARNING, logger="telethermal.ident.curvecache"):
        est = _estimator()
    assert est.family.g.shape[0] == SMALL["n_e"]
    assert "cannot write" in caplog.text and "memory" in caplog.text


def test_the_cache_folder_is_the_variable_else_xdg_else_home(monkeypatch, tmp_path):
    from telethermal.cachedir import cache_dir
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "own"))
    assert cache_dir() == tmp_path / "own"
    monkeypatch.delenv(CACHE_ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "xdg" / "telethermal"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache_dir() == tmp_path / "home" / ".cache" / "telethermal"


def test_the_suite_never_writes_the_users_cache():
    """tests/conftest.py points the variable at a temporary folder for the
    whole session (every process the suite starts inherits it)."""
    import os
    import tempfile
    from pathlib import Path
    assert Path(os.environ[CACHE_ENV]).is_relative_to(tempfile.gettempdir())
