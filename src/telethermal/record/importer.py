"""``telethermal dataset import``: recorded slave contacts (MCAP) and a lab's
own contacts (CSV) into the dataset format, so lab sessions grow the
identification database."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from telethermal.data.dataset import (MANIFEST, Trial, is_dataset_manifest, load_dataset,
                                      write_dataset)
from telethermal.errors import DatasetError
from telethermal.record.recording import read_recording

CHANNELS = ("t_s", "heat_flux_W_m2", "temperature_C", "force_N")


def trials_from_recording(path, material: str | None = None, group: str = "recorded",
                          room_c: float | None = None, scene=None) -> list[Trial]:
    """One trial per recorded slave contact. The material is the recording's
    (a simulated session knows it) unless ``material`` is given; a lab
    recording must be labelled by whoever placed the object. The room's
    temperature: ``room_c``, else the recorded scene's (``scene``, the
    :class:`~telethermal.physics.scene.Scene` it was made on, for a scene
    file's recording; a shipped one is found by its name)."""
    rec = read_recording(path)
    params = rec.config
    label = material or params.get("material")
    if not label:
        raise DatasetError(f"{path}: the recording does not say which material was touched; "
                           "pass --material")
    from telethermal.data.csv_import import check_material
    label = check_material(str(label), path)
    samples = rec.messages("/slave/samples")
    if not samples:
        raise DatasetError(f"{path}: no slave samples recorded (role {rec.role!r})")
    room_c = _room_c(path, params.get("scene"), scene) if room_c is None else room_c
    trials = []
    for i, s in enumerate(samples):
        missing = [c for c in CHANNELS if c not in s]
        if missing:
            raise DatasetError(f"{path}: recorded samples lack {', '.join(missing)}")
        channels = {c: np.asarray(s[c], dtype=np.float64) for c in CHANNELS}
        if len(channels["t_s"]) < 2:
            raise DatasetError(f"{path}: contact {i} has fewer than 2 samples")
        rate = 1.0 / float(np.median(np.diff(channels["t_s"])))
        stem = f"{Path(path).stem}-{i}"
        trials.append(Trial(stem, label, f"{label}/{stem}.csv", round(rate, 6),
                            float(s["object_ir_c"]), float(s["pad_before_c"]), float(room_c),
                            group, extra={"source": Path(path).name}, channels=channels))
    return trials


def _room_c(path, recorded: str | None, scene) -> float:
    """The room's temperature of the scene a recording names: ``scene`` if
    given (its name must be the recorded one), else a shipped scene or a
    scene file the recording names; else an error saying what to give."""
    from telethermal.errors import SceneError
    from telethermal.physics.scene import load_scene

    if scene is not None:
        if recorded is not None and scene.name != recorded:
            raise DatasetError(f"{path}: recorded on scene {recorded!r}, but --scene is "
                               f"{scene.name!r}")
        return scene.room_temp_c
    if recorded is not None:
        try:
            return load_scene(recorded).room_temp_c
        except SceneError:
            pass
    raise DatasetError(
        f"{path}: the room's temperature is not recorded and the recording's scene "
        f"{recorded!r} is not a shipped one: give the scene file it was made on "
        "(--scene FILE) or the room's temperature (--room-c)")


def _number(values: dict, key: str, where) -> float | None:
    value = values.get(key)
    if value in (None, ""):
        return None
    try:
        out = float(value)
    except ValueError:
        out = math.nan
    if not math.isfinite(out):
        raise DatasetError(f"{where}: {key} {value!r} is not a finite number")
    return out


def _dataset_trials(manifest, material, group, spec, values) -> list[Trial]:
    """The trials of the dataset whose manifest this is, as they are (its
    rows give each trial's material, group and temperatures)."""
    manifest = Path(manifest)
    if manifest.name != MANIFEST:
        raise DatasetError(f"{manifest}: a dataset's manifest (trial_id, sample_rate_hz, ...) "
                           f"is read with its folder, as {MANIFEST}")
    given = [o for o, v in (("--material", material), ("--group", group),
                            ("--columns", spec.columns), ("--units", spec.units),
                            ("--object-c/--pad-c/--room-c/--onset-s", values)) if v]
    if given:
        raise DatasetError(f"{manifest}: a dataset's manifest gives each trial's material, group "
                           f"and temperatures, in the dataset's format: not {', '.join(given)}")
    return load_dataset(manifest.parent)


def import_recordings(paths, into: str | Path, material: str | None = None,
                      group: str | None = None, spec=None, values: dict | None = None,
                      manifest: str | Path | None = None, scene=None) -> tuple[int, int]:
    """Add the files' contacts to the dataset at ``into`` (created if
    absent), all or nothing. Each file is told by its content: an MCAP
    recording (its slave contacts; ``scene``: the scene it was made on, if a
    scene file), or a lab's CSV of one contact
    (:mod:`telethermal.data.csv_import`, read with ``spec``; its per-trial
    ``values`` from the call, or its row of the lab's ``manifest``, which may
    also list the files). A ``manifest`` that is another dataset's adds that
    dataset's trials as they are. Returns (trials before, trials after)."""
    from telethermal.data.csv_import import CsvSpec, is_recording, lab_trial, read_lab_manifest

    into = Path(into)
    _check_into(into)
    spec = spec or CsvSpec({}, {})
    new = []
    if manifest is not None and Path(manifest).is_file() and is_dataset_manifest(manifest):
        new, manifest = _dataset_trials(manifest, material, group, spec, values), None
    rows = read_lab_manifest(manifest) if manifest is not None else {}
    for p in paths:
        if not Path(p).is_file():
            raise DatasetError(f"{p}: " + ("a folder, not a recording or CSV file"
                                           if Path(p).is_dir() else "no such file"))
    # One file, however it is spelt, once (the command line's and the manifest's).
    files = list(dict.fromkeys([str(Path(p).resolve()) for p in paths] + list(rows)))
    if not files and not new:
        raise DatasetError("no files to import: give them, or a --manifest listing them")
    existing = load_dataset(into) if (into / MANIFEST).is_file() else []
    for i, path in enumerate(files):
        per_trial = {"material": material, "group": group, **(values or {}),
                     **rows.get(path, {})}
        if is_recording(path):
            new += trials_from_recording(path, per_trial["material"],
                                         per_trial["group"] or "recorded",
                                         _number(per_trial, "T_room_C", path), scene)
            continue
        new.append(lab_trial(path, spec, per_trial, i))
    seen: dict[str, str] = {}
    for t in new:
        source = t.extra.get("source", "?")
        if t.trial_id in seen:
            raise DatasetError(f"{source} and {seen[t.trial_id]} give the same trial "
                               f"{t.trial_id!r} (the same contact twice?)")
        seen[t.trial_id] = source
    ids = {t.trial_id for t in existing}
    clash = [t.trial_id for t in new if t.trial_id in ids]
    if clash:
        raise DatasetError(f"{into} already holds {', '.join(clash[:3])}: imported before?")
    write_dataset(into, existing + new, overwrite=True)
    return len(existing), len(existing) + len(new)


def _check_into(into: Path) -> None:
    """``--into`` must be a dataset (its manifest there), an empty folder or
    a path not yet taken: anything else would be replaced by the dataset."""
    if not into.exists():
        return
    if not into.is_dir():
        raise DatasetError(f"--into {into}: a file, not a dataset folder (give a new or empty "
                           "folder, or a dataset's)")
    if is_dataset_manifest(into / MANIFEST):
        return
    held = sorted(p.name + ("/" if p.is_dir() else "") for p in into.iterdir())
    if not held:
        return
    parts = [d for d in ("pad", "finger") if (into / d / MANIFEST).is_file()]
    hint = (f"a generated database folder: give {into / parts[0]} to add to its "
            f"{parts[0]} contacts, or a new folder" if parts
            else "give a new or empty folder, or a dataset's")
    raise DatasetError(f"--into {into}: not a dataset (no {MANIFEST}) and not empty (it holds "
                       f"{', '.join(held[:5])}{', ...' if len(held) > 5 else ''}), and importing "
                       f"would replace what it holds: {hint}")
