"""Train what a session needs, from a scene's simulated databases (in
memory), when no saved identifier or generator is given."""

from __future__ import annotations

import hashlib
import logging
from contextlib import nullcontext
from pathlib import Path

import numpy as np

from telethermal.data.generate import finger_database, pad_database
from telethermal.ident.fitted import serves
from telethermal.ident.prepare import from_trials
from telethermal.ident.registry import load_model, make, with_fallback
from telethermal.physics.scene import Scene
from telethermal.render.generator import NetworkGenerator, load_generator


log = logging.getLogger(__name__)

#: The identifier a session trains when given none, on a scene it can model
#: (:func:`default_method`).
DEFAULT_METHOD = "effusivity-fit"
#: The identifier trained on a scene the default cannot model.
FALLBACK_METHOD = "effusivity-lda"


def default_method(scene: Scene) -> str:
    """:data:`DEFAULT_METHOD` where it can model ``scene``'s touches, else
    :data:`FALLBACK_METHOD` (logged, with the reason)."""
    method, why = method_and_reason(scene)
    if method != DEFAULT_METHOD:
        log.info("%s: identifier %s, not %s: %s", scene.name, FALLBACK_METHOD, DEFAULT_METHOD,
                 why)
    return method


def method_and_reason(scene: Scene) -> tuple[str, str]:
    """(:func:`default_method`'s method for ``scene``, why: one line)."""
    reason = serves(scene)
    if reason is None:
        return DEFAULT_METHOD, f"it fits {scene.name}'s pad model to each touch"
    return FALLBACK_METHOD, f"{DEFAULT_METHOD} cannot model {scene.name}'s touches: {reason}"


def train_identifier(scene: Scene, seed: int = 0, method: str | None = None,
                     calibration=None, fallback: bool = True):
    """Database 1 of ``scene`` (seed ``seed``) -> a fitted ``method``
    identifier (default: :func:`default_method`); ``calibration``: the
    pad's (a PadCalibration), for the methods that fit its model;
    ``fallback``: with its model-free fallback (:func:`with_fallback`)."""
    method = method or default_method(scene)
    trials = pad_database(scene, np.random.default_rng(seed))
    contacts = from_trials(trials)[0]
    model = make(method, scene=scene, calibration=calibration).fit(contacts)
    model.scene_ = scene.name
    return with_fallback(model, contacts) if fallback else model



def train_generator(scene: Scene, seed: int = 0):
    """Database 2 of ``scene`` (a scene with a finger) -> a fitted generator.

    The network generator is the default: on held-out persons it renders
    closer to the recorded flux than the fitted closed form (see
    ``telethermal bench render``, ``generator`` section)."""
    trials = finger_database(scene, np.random.default_rng(seed + 1000))
    return NetworkGenerator().fit(trials)


def session_models(scene: Scene, identifier_path=None, generator_path=None, seed: int = 0,
                   status=nullcontext):
    """The saved identifier and generator, or, where no path is given, one
    trained on ``scene``'s databases (simulated in memory with ``seed``).
    ``status(text)``: a context manager held while each loads or trains (a
    console's spinner, say)."""
    with status("identifier: " + ("loading" if identifier_path else
                                  f"training on {scene.name}'s pad database")):
        identifier = load_model(identifier_path) if identifier_path else \
            train_identifier(scene, seed)
    with status("generator: " + ("loading" if generator_path else
                                 f"training on {scene.name}'s finger database")):
        generator = load_generator(generator_path) if generator_path else \
            train_generator(scene, seed)
    return identifier, generator


def write_models(out, scene_name: str = "fingertip-7", data=None, seed: int = 0,
                 echo=log.info, calibration: str | None = None) -> list:
    """A slave host's ``identifier.npz`` and ``generator.npz`` in ``out``,
    with ``SHA256SUMS`` (``sha256sum -c`` checks a copy). Trained on the
    scene's simulated databases (as the slave does at start when its config
    names no files), or on a dataset folder ``data``: ``pad/`` and
    ``finger/`` (a generated or a recorded one), or one dataset of pad
    contacts (a lab's import). Without a finger database the generator is
    the scene's direct-contact model (its simulated finger database: the
    closed forms and layered solutions the simulator is checked against).
    ``echo(line)``: told which identifier was trained and why;
    ``calibration``: the pad's CAL.toml (``telethermal calibrate pad``)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(20, "a file, not the models' folder", str(out))
    # Made now, so a folder that cannot be made is said before any training;
    # removed again if nothing is written into it, with the parents made for
    # it (deepest first, each only while empty).
    made = [p for p in (out, *out.parents) if not p.exists()]
    out.mkdir(parents=True, exist_ok=True)
    try:
        return _write_models(out, scene_name, data, seed, echo, calibration)
    except BaseException:
        for folder in made:
            try:
                folder.rmdir()
            except OSError:             # not empty (or not ours to remove): kept
                break
        raise


def _write_models(out: Path, scene_name: str, data, seed: int, echo, calibration) -> list:
    from telethermal.data.dataset import load_dataset
    from telethermal.physics.scene import load_scene
    from telethermal.render.generator import save_generator
    from telethermal.physics.scene import with_finger

    from telethermal.ident.pad_calibration import pad_calibration
    scene = with_finger(load_scene(scene_name))
    cal = pad_calibration(calibration or "", scene)
    if data is None:
        method, why = method_and_reason(scene)
        identifier = train_identifier(scene, seed, method, calibration=cal)
        generator = train_generator(scene, seed)
    else:
        from telethermal.data.dataset import MANIFEST, trial_digest
        from telethermal.ident.registry import dataset_scene, pad_dataset
        pad = pad_dataset(data)
        trials = load_dataset(pad)
        named = dataset_scene(pad)                      # None when it has no record
        method, data_scene, why = _dataset_method(scene, named)
        contacts = from_trials(trials)[0]
        identifier = make(method, scene=data_scene, calibration=cal).fit(contacts)
        identifier.scene_ = named
        with_fallback(identifier, contacts)
        identifier.training_digests_ = sorted({trial_digest(t) for t in trials})
        finger = Path(data) / "finger"
        generator = NetworkGenerator().fit(load_dataset(finger)) \
            if (finger / MANIFEST).is_file() else train_generator(scene, seed)
    echo(f"identifier: {method} on {', '.join(identifier.classes_)}: {why}")
    if identifier.fallback_ is not None:
        echo(f"fallback: {identifier.fallback_.method} on the same touches, in the same file: "
             f"it names a touch {method}'s pad-model check refuses (pad model does not fit)")
    paths = [Path(identifier.save(out / "identifier.npz")),
             Path(save_generator(generator, out / "generator.npz"))]
    return paths + [write_sums(out, paths)]


def read_sums(folder) -> dict[str, str]:
    """``folder/SHA256SUMS`` as {file name: sha256} (``sha256sum``'s text
    and binary lines, ``name`` and ``*name``); empty if there is none."""
    sums = Path(folder) / "SHA256SUMS"
    if not sums.is_file():
        return {}
    listed = {}
    for line in sums.read_text().splitlines():
        digest, _, name = line.partition(" ")
        listed[name.strip().removeprefix("*")] = digest.strip()
    return listed


def write_sums(out, paths) -> Path:
    """``out/SHA256SUMS`` for ``paths`` (files in ``out``), in
    ``sha256sum``'s format; returns its path."""
    sums = Path(out) / "SHA256SUMS"
    sums.write_text("".join(f"{hashlib.sha256(Path(p).read_bytes()).hexdigest()}  "
                            f"{Path(p).name}\n" for p in paths))
    return sums


def _dataset_method(scene: Scene, named: str | None):
    """(the method, the scene, why) for a dataset of the scene ``named``
    (None: the dataset names none): :func:`default_method` of that scene;
    :data:`FALLBACK_METHOD` where the dataset names no scene or one this
    process cannot load (its pad's model is what the default fits)."""
    from telethermal.errors import IdentificationError
    from telethermal.ident.fitted import scene_of

    if named is None:
        return FALLBACK_METHOD, None, (
            f"the dataset names no scene, whose pad model {DEFAULT_METHOD} would fit (a lab's "
            f"import: give it a generation.json naming its scene, or use `identify train "
            f"--scene`)")
    try:
        data_scene = scene if named == scene.name else scene_of(named)
    except IdentificationError as exc:
        return FALLBACK_METHOD, None, str(exc)
    method, why = method_and_reason(data_scene)
    return method, data_scene, why


def demo_identify(scene, out, seed: int, echo=print, method: str | None = None,
                  calibration=None):
    """Train telethermal's identifier (``method``, default: :func:`default_method`;
    with its model-free fallback where it fits a pad model, as the slave
    service's :func:`train_identifier`) on ``out/databases/pad`` and score it on fresh trials of the same scene
    (seed ``seed + 1``): writes ``identifier.npz``, ``identify.json`` and
    ``identify.png`` in ``out``, echoes one line; returns the model.
    ``calibration``: the pad's (a PadCalibration), for the methods that fit
    its model (recorded in the model file)."""

    from telethermal.jsonfile import write_json

    from telethermal.data.dataset import load_dataset
    from telethermal.ident.evaluate import evaluate, plot_accuracy

    out = Path(out)
    method = method or default_method(scene)
    contacts = from_trials(load_dataset(out / "databases" / "pad"))[0]
    model = make(method, scene=scene, calibration=calibration).fit(contacts)
    model.scene_ = scene.name
    model = with_fallback(model, contacts)     # as the slave service trains it
    model.save(out / "identifier.npz")
    report = evaluate(model, pad_database(scene, np.random.default_rng(seed + 1)))
    write_json(out / "identify.json", report)
    plot_accuracy({model.method: report}, out / "identify.png",
                  f"{scene.name}: trained on seed {seed}, tested on seed {seed + 1}")
    acc = report["accuracy_by_window_s"]
    echo(f"identification ({model.method}, fresh trials): "
         + ", ".join(f"{k} s {100 * v:.0f} %" for k, v in acc.items() if k in ("0.2", "0.5", "1.0"))
         + (f"; 5 merged classes at 1 s {100 * report['accuracy_5_at_end']:.0f} %"
            if "accuracy_5_at_end" in report else "")
         + f"; decisions {report['decision_time_s']['n']}/{report['trials']} committed")
    return model
