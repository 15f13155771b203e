"""The effusivity estimator's curve family on disk: a per-user cache.

The curves (:func:`~telethermal.ident.effusivity_curves.effusivity_family`) take
seconds to build (the pad's loop simulated at 1 kHz for every grid point)
and depend only on what this module's key names: the scene's pad (layers,
module, heat sink, contact conductance), its room, rate, flux sensor lag and
model tolerance, the reference material's properties, the object
temperature, the grids (ln e, ln h, t) and the source of the code that
computes them. A process that needs a family it finds here reads it instead
(``allow_pickle=False``, through :mod:`telethermal.npzfile`); else it builds
and writes it (atomically: a crash leaves the old file or none).

Where: ``$TELETHERMAL_CACHE``, else ``$XDG_CACHE_HOME/telethermal``, else
``~/.cache/telethermal``. A file that cannot be read or does not hold what
its name says is rebuilt (logged); a folder that cannot be written leaves
the family built in memory (logged).
"""

from __future__ import annotations

import hashlib
import json
import logging
from importlib import resources
from pathlib import Path

import numpy as np

from telethermal import __version__
from telethermal.cachedir import cache_dir
from telethermal.errors import ModelFileError
from telethermal.ident.effusivity_curves import (EFFUSIVITY_RANGE_W_S05_M2K, MODEL_DT_S, N_E,
                                                 REFERENCE_MATERIAL, EffusivityFamily)
from telethermal.ident.effusivity_curves import effusivity_family
from telethermal.npzfile import read_npz, write_npz

log = logging.getLogger(__name__)

FORMAT = "telethermal-effusivity-curves"
FORMAT_VERSION = 1
#: The package folders whose source computes the curves: an edit to any of
#: them (a release or not) is another key.
SOURCE_FOLDERS = ("physics", "ident/effusivity.py", "ident/effusivity_curves.py",
                  "ident/oracle.py", "data/generate.py")


def _source_digest() -> str:
    root = resources.files("telethermal")
    h = hashlib.blake2b(digest_size=16)
    for entry in SOURCE_FOLDERS:
        node = root.joinpath(entry)
        files = [node] if node.is_file() else sorted(
            (f for f in node.iterdir() if f.is_file() and f.name.endswith((".py", ".csv",
                                                                            ".toml"))),
            key=lambda f: f.name)
        for f in files:
            h.update(f"{entry}/{f.name}".encode())
            h.update(f.read_bytes())
    return h.hexdigest()


def family_key(scene, object_temp_c: float, u_grid, t_max_s: float, n_e: int, e_range,
               dt_s: float) -> dict:
    """Everything the family's values depend on, as JSON-able text and
    numbers (floats by ``repr``: exact)."""
    from telethermal.physics.materials import get_material
    return {
        "pad": repr(scene.pad), "module": repr(scene.pad.module_params()),
        "room_temp_c": repr(float(scene.room_temp_c)),
        "sample_rate_hz": repr(float(scene.sample_rate_hz)),
        "flux_lag_s": repr(float(scene.sensors.flux_lag_s)),
        "tolerance_rel": repr(float(scene.tolerance_rel)),
        "reference": repr(get_material(REFERENCE_MATERIAL)),
        "object_temp_c": repr(float(object_temp_c)),
        "u_grid": [repr(float(u)) for u in np.asarray(u_grid, float)],
        "t_max_s": repr(float(t_max_s)), "n_e": int(n_e),
        "e_range_w_s05_m2k": [repr(float(e)) for e in e_range], "dt_s": repr(float(dt_s)),
        "format_version": FORMAT_VERSION, "telethermal_version": __version__,
        "source": _source_digest()}


def key_digest(key: dict) -> str:
    return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:32]


def _read(path: Path, digest: str):
    """The family stored at ``path``, or None (logged) when it is not one
    or not the one ``digest`` names."""
    try:
        header, arrays = read_npz(path, FORMAT, FORMAT_VERSION, "effusivity curves")
        if header.get("key_digest") != digest:
            raise ModelFileError(f"{path}: holds curves of key {header.get('key_digest')}, "
                                 f"not {digest}")
        grids = [arrays[k] for k in ("log_e", "u", "t_s", "g")]
        if grids[3].shape != tuple(len(a) for a in grids[:3]):
            raise ModelFileError(f"{path}: g has shape {grids[3].shape}, the grids "
                                 f"{[len(a) for a in grids[:3]]}")
        if not np.all(np.isfinite(grids[3])):
            raise ModelFileError(f"{path}: g holds NaN or inf")
        return EffusivityFamily.from_grid(*grids)
    except (ModelFileError, KeyError, ValueError) as exc:
        log.warning("effusivity curves cache: %s; rebuilding them", exc)
        return None


def cached_family(scene, object_temp_c: float, u_grid, t_max_s: float, n_e: int = N_E,
                  e_range=EFFUSIVITY_RANGE_W_S05_M2K,
                  dt_s: float = MODEL_DT_S) -> EffusivityFamily:
    """:func:`~telethermal.ident.effusivity_curves.effusivity_family` of these
    arguments (its signature), read from the cache when it holds it, else
    built and written there."""
    digest = key_digest(family_key(scene, object_temp_c, u_grid, t_max_s, n_e, e_range, dt_s))
    path = cache_dir() / f"curves-{digest}.npz"
    if path.exists():
        family = _read(path, digest)
        if family is not None:
            log.debug("effusivity curves of %s read from %s", scene.name, path)
            return family
    family = effusivity_family(scene, object_temp_c, u_grid, t_max_s, n_e, e_range, dt_s)
    arrays = {"log_e": family.log_e, "u": family.u, "t_s": family.t_s, "g": family.g}
    try:
        write_npz(path, FORMAT, FORMAT_VERSION, {"key_digest": digest, "scene": scene.name},
                  arrays)
        log.info("effusivity curves of %s cached in %s", scene.name, path)
    except OSError as exc:
        log.warning("effusivity curves cache: cannot write %s (%s); the curves stay in "
                    "memory for this process", path, exc)
    return family
