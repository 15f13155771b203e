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
    which files, by their sha256). BenchError
    names the folder and what is wrong: a file missing, unreadable, not
    matching its ``SHA256SUMS`` line, or trained on another scene."""
    if models is None:
        from telethermal.teleop.models import train_generator, train_identifier
        return (train_identifier(scene, TRAINING_SEED), train_generator(scene, TRAINING_SEED),
                {"trained": True, "scene": scene.name, "seed": TRAINING_SEED})
    from telethermal.ident.registry import load_model
    from telethermal.render.generator import load_generator

    folder = Path(models)
    remake = f"`telethermal models --scene {scene.ref or scene.name} --out {folder}`"
    digests = _checked(folder, remake)
    try:
        identifier = load_model(folder / FILES[0])
        generator = load_generator(folder / FILES[1])
    except TelethermalError as exc:
        raise BenchError(f"--models {folder}: {exc}; write them again with {remake}") from exc
    if getattr(identifier, "scene_", None) != scene.name:
        raise BenchError(f"--models {folder}: its identifier was trained on "
                         f"{getattr(identifier, 'scene_', None) or 'no named scene'}, this "
                         f"bench runs {scene.name}; write them with {remake}")
    return (identifier, generator,
            {"trained": False, "scene": scene.name, "files": digests})


def _checked(folder: Path, remake: str) -> dict:
    """{file name: sha256} of the folder's two files, each against its line in
    ``SHA256SUMS`` (which ``telethermal models`` writes beside them)."""
    if not folder.is_dir():
        raise BenchError(f"--models {folder}: no such folder; write it with {remake}")
    sums = folder / "SHA256SUMS"
    listed = {}
    if sums.is_file():
        for line in sums.read_text().splitlines():
            digest, _, name = line.partition("  ")
            listed[name.strip()] = digest.strip()
    digests = {}
    for name in FILES:
        path = folder / name
        if not path.is_file():
            raise BenchError(f"--models {folder}: no {name}; write it with {remake}")
        digests[name] = hashlib.sha256(path.read_bytes()).hexdigest()
        if name not in listed:
            raise BenchError(f"--models {folder}: {sums.name} lists no {name} (a folder "
                             f"telethermal models did not write whole); write it with {remake}")
        if listed[name] != digests[name]:
            raise BenchError(f"--models {folder}: {name} does not match {sums.name} (a partial "
                             f"or other copy); write it again with {remake}")
    return digests
