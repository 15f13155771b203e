"""Identification methods by name, and loading a saved model of any method."""

from __future__ import annotations

import logging
import time
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path

from telethermal.data.dataset import load_dataset, trial_digest
from telethermal.errors import DatasetError, IdentificationError, ModelFileError
from telethermal.ident.base import (FALLBACK_PREFIX, Identifier, check_identifier_header,
                                   read_model_file)
from telethermal.ident.fitted import EffusivityFit
from telethermal.ident.methods import EffusivityLda, PcaFnn
from telethermal.ident.prepare import MIN_GAP_K, from_trials
from telethermal.ident.recurrent import Lstm, Rnn
from telethermal.physics.scene import Scene

log = logging.getLogger(__name__)
METHODS: dict[str, type[Identifier]] = {m.method: m for m in (PcaFnn, EffusivityLda,
                                                                EffusivityFit, Lstm, Rnn)}


def make(method: str, scene: str | None = None, calibration=None, **kw) -> Identifier:
    """A ``method`` identifier; ``scene`` (the touches' scene: a Scene, a
    name or a path) and ``calibration`` (its pad's: a PadCalibration or a
    CAL.toml path) are given to the methods that fit its pad's model and
    ignored by the others."""
    try:
        cls = METHODS[method]
    except KeyError as exc:
        raise IdentificationError(f"unknown method {method!r}; methods: "
                                  f"{', '.join(sorted(METHODS))}") from exc
    if scene is not None and getattr(cls, "needs_scene", False):
        kw["scene"] = scene if isinstance(scene, Scene) else str(scene)
    if calibration is not None and getattr(cls, "needs_scene", False):
        kw["calibration"] = calibration
    return cls(**kw)


def load_model(path: str | Path) -> Identifier:
    header, arrays = read_model_file(path)
    model = _restored(path, header, arrays)
    fallback = header.get("fallback")
    if fallback is not None:
        if not isinstance(fallback, dict):
            raise ModelFileError(f"{path}: fallback must be a model's header")
        check_identifier_header(Path(path), fallback)
        model.fallback_ = _restored(path, fallback, {
            k[len(FALLBACK_PREFIX):]: v for k, v in arrays.items()
            if k.startswith(FALLBACK_PREFIX)})
        if list(model.fallback_.classes_) != list(model.classes_):
            raise ModelFileError(f"{path}: the fallback's classes {model.fallback_.classes_} "
                                 f"are not the model's {model.classes_}")
    return model


def with_fallback(model: Identifier, contacts) -> Identifier:
    """``model`` with an ``effusivity-lda`` identifier trained on the same
    ``contacts`` and channels as its ``fallback_``, where ``model`` fits a
    pad model (its pad-model check can refuse a touch: the fallback, which
    needs none, then names it; ``anytime.fallen_back``); other models as
    they are."""
    if getattr(model, "misfit", None) is not None:
        model.fallback_ = EffusivityLda(channels=tuple(model.channels)).fit(contacts)
        model.fallback_.scene_ = model.scene_
    return model


def _restored(path, header: dict, arrays: dict) -> Identifier:
    cls = METHODS.get(header.get("method"))
    if cls is None:
        raise ModelFileError(f"{path}: method {header.get('method')!r} is not one this "
                             f"telethermal knows ({', '.join(sorted(METHODS))})")
    return cls.restore(header, arrays)


def dataset_scene(data_dir: str | Path) -> str | None:
    """The scene a generated dataset came from (its ``generation.json``, in
    the dataset folder or its parent), or None for a dataset without one."""
    import json

    for folder in (Path(data_dir), Path(data_dir).parent):
        meta = folder / "generation.json"
        if meta.is_file():
            try:
                return json.loads(meta.read_text()).get("scene")
            except (OSError, ValueError):
                return None
    return None


def check_scene(model: Identifier, scene_name: str, where: str = "the identifier",
                scene_materials=None) -> None:
    """Refuse a model trained (and calibrated) on another scene: its
    sensors, pad and gap differ, so its posteriors would mean nothing. A
    model from data that name no scene (a lab's imported contacts) is
    refused where it knows materials the scene's objects are not
    (``scene_materials``): it was made for other objects."""
    trained = model.scene_
    if trained is not None and trained != scene_name:
        raise ModelFileError(f"{where} was trained and calibrated on scene {trained!r}; this "
                             f"runs scene {scene_name!r}. Train one on {scene_name!r} "
                             "(telethermal identify train) or run the scene it was made for")
    if trained is None and scene_materials is not None:
        foreign = [c for c in model.classes_ if c not in set(scene_materials)]
        if foreign:
            raise ModelFileError(
                f"{where} was trained on data that name no scene, on {', '.join(model.classes_)}; "
                f"scene {scene_name!r} has objects of {', '.join(scene_materials)}: "
                f"{', '.join(foreign)} {'is' if len(foreign) == 1 else 'are'} not among them. "
                f"Give the scene those objects, or train on contacts of its materials")


def pad_dataset(data: str | Path) -> Path:
    """``data``, or ``data/pad`` where ``data`` holds a generated scene's
    databases (``pad/`` and ``finger/``: identification reads the pad's)."""
    from telethermal.data.dataset import MANIFEST

    root = Path(data)
    if not (root / MANIFEST).is_file() and (root / "pad" / MANIFEST).is_file():
        log.info("%s holds the databases pad/ and finger/: identification reads %s", root,
                 root / "pad")
        return root / "pad"
    if _finger_database(root / MANIFEST):
        pad = root.parent / "pad"
        raise IdentificationError(
            f"{root} is a finger database (fingertip touches, the generator's), not the pad's "
            "touches" + (f": give {pad}" if (pad / MANIFEST).is_file() else ""))
    return root


def _finger_database(manifest: Path) -> bool:
    """Whether ``manifest`` is a generated finger database's (its columns
    name the person and the finger's true temperature)."""
    from telethermal.data.dataset import manifest_header
    try:
        header = manifest_header(manifest)
    except (OSError, DatasetError):
        return False                     # the dataset's own reader says what is wrong
    return {"person", "T_finger_true_C"} <= header


def touches_scene(data: str | Path, scene: Scene | None):
    """The scene whose pad made the touches of ``data``: ``scene`` (a
    user's ``--scene``; refused when the dataset records another), else the
    one the dataset records (its name; None for a lab's import)."""
    named = dataset_scene(data)
    if scene is None:
        return named
    if named is not None and named != scene.name:
        raise IdentificationError(
            f"{data} was generated from scene {named!r} (its generation.json), not "
            f"{scene.name!r}: give --scene {named} (or that scene's file)")
    return scene


def scene_name(scene) -> str | None:
    """A scene's name (a Scene, or a name already), None for none."""
    return getattr(scene, "name", scene)


@dataclass(frozen=True)
class Trained:
    """A model fitted and saved by :func:`train_on_dataset`."""

    model: Identifier
    path: Path
    skipped: list         # trials left out: a gap under MIN_GAP_K
    train_s: float        # fitting and saving


def train_on_dataset(data: str | Path, method: str, channels, max_window_s: float,
                     out: str | Path, status=nullcontext, logger=log,
                     unseen_weight: float | None = None, scene: Scene | None = None,
                     calibration=None) -> Trained:
    """Fit a ``method`` identifier on the dataset folder ``data`` (or its
    ``pad/``) and save it to ``out``, with the touches' scene: ``scene``,
    else the dataset's record of one (:func:`touches_scene`).
    ``status(text)``: a context manager held while reading and fitting;
    ``logger`` warns of trials left out. ``unseen_weight``: effusivity-fit's
    prior weight of a material outside the classes (its default if None)."""
    data = pad_dataset(data)
    scene = touches_scene(data, scene)
    extra = {}
    if unseen_weight is not None:
        if method != "effusivity-fit":
            raise IdentificationError(f"--unseen-weight is effusivity-fit's (it weighs a "
                                      f"material outside the classes by its effusivity "
                                      f"estimate); {method} has none")
        extra["unseen_weight"] = unseen_weight
    with status(f"reading {data}"):
        trials = load_dataset(data)
    model = make(method, scene=scene, calibration=calibration, channels=channels,
                 max_window_s=max_window_s, **extra)
    contacts, skipped = from_trials(trials, model.channels, max_s=max_window_s)
    if skipped:
        logger.warning("%d trial(s) with a gap under %g K left out of training", len(skipped),
                       MIN_GAP_K)
    start = time.perf_counter()
    with status(f"training {method} on {len(contacts)} trials"):
        model.fit(contacts)
    if scene is not None:
        model.scene_ = scene_name(scene)
    keep = {id(t) for t in trials} - {id(t) for t in skipped}
    model.training_digests_ = sorted({trial_digest(t) for t in trials if id(t) in keep})
    path = model.save(out)
    return Trained(model, Path(path), skipped, time.perf_counter() - start)
