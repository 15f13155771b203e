"""The identifier and generator a bench's sessions run on: trained in the
bench on its scene's simulated databases (seed :data:`TRAINING_SEED`, as a
session trains them when given none), or loaded from a folder that
``telethermal models --scene S --out DIR`` wrote (``--models DIR``: ``make
bench`` and ``make bench-quick`` train them once for all their benches; the
same files byte for byte, so the same figures).

Each bench records which in its JSON (``models``: the third of what
:func:`bench_models` returns)."""

from __future__ import annotations

import hashlib
from pathlib import Path

from telethermal.errors import BenchError, TelethermalError

#: The simulated databases' seed the benches train on.
TRAINING_SEED = 0
FILES = ("identifier.npz", "generator.npz")


def bench_models(scene, models: str | Path | None = None):
    """(identifier, generator, provenance) for ``scene``'s sessions: trained
    here, or loaded from ``models`` (a folder of ``telethermal models``);
    provenance: the JSON's ``models`` (trained on which scene and seed, or
    which files, by their sha256). BenchError names the folder and what is
    wrong: a file missing, unreadable or not matching its ``SHA256SUMS``
    line, an identifier trained on another scene, on a dataset or with a
    pad calibration. The folder does not record the databases' seed: the
    Makefile writes it with seed :data:`TRAINING_SEED`, and the sha256 in
    the JSON name the files. Either way the identifier is prepared
    (``prepare``): what it builds on its first posterior is built before
    any timed session."""
    if models is None:
        from telethermal.teleop.models import train_generator, train_identifier
        return (train_identifier(scene, TRAINING_SEED).prepare(),
                train_generator(scene, TRAINING_SEED),
                {"trained": True, "scene": scene.name, "seed": TRAINING_SEED})
    from telethermal.ident.registry import load_model
    from telethermal.render.generator import load_generator

    folder = Path(models)
    remake = f"`telethermal models --scene {scene.ref or scene.name} --out {folder}`"
    digests = checked_folder(folder, remake)
    try:
        identifier = load_model(folder / FILES[0])
        generator = load_generator(folder / FILES[1])
    except TelethermalError as exc:
        raise BenchError(f"--models {folder}: {exc}; write them again with {remake}") from exc
    if getattr(identifier, "scene_", None) != scene.name:
        raise BenchError(f"--models {folder}: its identifier was trained on "
                         f"{getattr(identifier, 'scene_', None) or 'no named scene'}, this "
                         f"bench runs {scene.name}; write them with {remake}")
    other = ("a dataset (models --data)" if getattr(identifier, "training_digests_", None)
             else "a pad calibration (models --calibration)"
             if getattr(identifier, "calibration", None) is not None else None)
    if other:
        raise BenchError(f"--models {folder}: its identifier was trained on {other}, not on "
                         f"the scene's simulated databases the bench trains on; write them "
                         f"with {remake}")
    # What a loaded model builds on its first posterior (the effusivity
    # estimator's curves, torch), built now: not in a timed session.
    identifier = identifier.prepare()
    return (identifier, generator,
            {"trained": False, "scene": scene.name, "files": digests})


def checked_folder(folder: str | Path, remake: str = "`telethermal models --out DIR`") -> dict:
    """{file name: sha256} of the folder's two files, each against its line in
    ``SHA256SUMS`` (which ``telethermal models`` writes beside them; a line
    of ``sha256sum -b``, ``*name``, read too); BenchError naming the folder
    and what is wrong."""
    folder = Path(folder)
    if not folder.is_dir():
        raise BenchError(f"--models {folder}: no such folder; write it with {remake}")
    sums = folder / "SHA256SUMS"
    if not sums.is_file():
        raise BenchError(f"--models {folder}: no SHA256SUMS beside the models (a folder "
                         f"telethermal models did not write); write it with {remake}")
    from telethermal.teleop.models import read_sums
    try:
        listed = read_sums(folder)
        digests = {}
        for name in FILES:
            path = folder / name
            if not path.is_file():
                raise BenchError(f"--models {folder}: no {name}; write it with {remake}")
            digests[name] = hashlib.sha256(path.read_bytes()).hexdigest()
    except (OSError, UnicodeDecodeError) as exc:
        raise BenchError(f"--models {folder}: cannot read it ({exc})") from exc
    for name in FILES:
        if name not in listed:
            raise BenchError(f"--models {folder}: {sums.name} lists no {name} (a folder "
                             f"telethermal models did not write whole); write it with {remake}")
        if listed[name] != digests[name]:
            raise BenchError(f"--models {folder}: {name} does not match {sums.name} (a partial "
                             f"or other copy); write it again with {remake}")
    return digests
