"""``telethermal scenes``, ``dataset generate|show|validate|import`` and
``simulate``."""

from __future__ import annotations

import time
from pathlib import Path

from telethermal.cli._common import (CONTACT_MAX_S, CONTACT_WHY, _positive, _progress, _seed,
                                     _temperature_c, console, log)


def cmd_scenes(args) -> int:
    if args.write_idle_policy:
        return _write_idle_policies(args.write_idle_policy)
    from rich.console import Console
    from rich.table import Table

    from telethermal.physics.scene import describe_models, list_scenes, load_scene

    # Every scene read (and checked) before the table is shown.
    scenes = [load_scene(name) for name in (args.scene or list_scenes())]
    table = Table(title="scenes" if args.scene else "shipped scenes")
    for col in ("name", "pad", "rate (Hz)", "objects", "finger"):
        table.add_column(col)
    for scene in scenes:
        table.add_row(scene.name, scene.pad.kind, f"{scene.sample_rate_hz:g}",
                      ", ".join(scene.materials), "yes" if scene.finger else "no")
        if args.verbose:
            for side, material, choice in describe_models(scene):
                table.add_row("", side, "", material, choice.describe())
    Console().print(table)
    return 0


def cmd_dataset_generate(args) -> int:
    from telethermal.data.generate import generate_databases
    from telethermal.physics.scene import describe_models, load_scene

    scene = load_scene(args.scene)
    for side, material, choice in describe_models(scene):
        log.info("%s on %s: %s", side, material, choice.describe())
    parts = 2 if scene.finger is not None else 1
    start = time.perf_counter()
    with _progress(parts, f"generating {scene.name}") as advance:
        summary = generate_databases(scene, args.out, seed=args.seed, overwrite=args.force,
                                     progress=advance)
    for name, info in summary["datasets"].items():
        print(f"{Path(args.out) / name}: {info['trials']} trials of "
              f"{', '.join(info['materials'])}")
    print(f"done in {time.perf_counter() - start:.1f} s")
    return 0


def cmd_dataset_show(args) -> int:
    from telethermal.data.plots import plot_datasets

    with console.status(f"reading and plotting {args.dir}"):
        png = plot_datasets(args.dir, args.out)
    print(png)
    return 0


def cmd_dataset_validate(args) -> int:
    from telethermal.data.dataset import check_identifier_channels, load_dataset

    with console.status(f"reading {args.dir}"):
        trials = load_dataset(args.dir)
    check_identifier_channels(trials, args.dir)
    materials = sorted({t.material for t in trials})
    channels = sorted({c for t in trials for c in t.channels})
    print(f"{args.dir}: {len(trials)} trials, materials {', '.join(materials)}; "
          f"channels {', '.join(channels)}")
    return 0


def cmd_dataset_import(args) -> int:
    from telethermal.data.csv_import import CsvSpec
    from telethermal.record.importer import import_recordings

    values = {k: v for k, v in (("T_object_C", args.object_c), ("T_pad_C", args.pad_c),
                                ("T_room_C", args.room_c), ("onset_s", args.onset_s))
              if v is not None}
    scene = None
    if args.scene:
        from telethermal.physics.scene import load_scene
        scene = load_scene(args.scene)
    before, after = import_recordings(args.files, args.into, args.material, args.group,
                                      CsvSpec.from_options(args.columns, args.units), values,
                                      args.manifest, scene)
    print(f"{args.into}: {before} trials before, {after} now")
    return 0


def cmd_simulate(args) -> int:
    from telethermal.data.dataset import write_dataset
    from telethermal.data.generate import single_contact

    trial = single_contact(args.pad, args.object, args.pad_temp_c, args.object_temp_c,
                           args.seconds, args.rate_hz, ideal=args.ideal, seed=args.seed,
                           contact_conductance_w_m2k=args.contact_conductance_w_m2k)
    write_dataset(args.out, [trial], overwrite=args.force)
    print(f"{Path(args.out) / trial.file}: {len(trial.channels['t_s'])} samples")
    return 0


def _write_idle_policies(names) -> int:
    """Compute and write the package's idle policy of each shipped scene
    (developers: after changing a shipped scene, the module, the materials
    or the search; a few minutes each)."""
    from telethermal.control.preconditioning import compute_policy, shipped_policy_path
    from telethermal.jsonfile import write_json
    from telethermal.physics.scene import load_scene
    from telethermal.physics.scene import with_finger

    for name in names:
        scene = with_finger(load_scene(name))
        path = Path(str(shipped_policy_path(scene.name)))
        write_json(path, compute_policy(scene))
        print(f"{path}: the idle policy of {scene.name}")
    return 0


def add_scenes(sub) -> None:
    p = sub.add_parser("scenes", help="list the shipped scenes, or show the scenes given")
    p.add_argument("--scene", action="append", metavar="FILE|NAME",
                   help="show this scene instead (a shipped name or a TOML path, read and "
                        "checked; repeat for more)")
    p.add_argument("--verbose", "-v", action="store_true", help="show each contact's model")
    p.add_argument("--write-idle-policy", nargs="+", metavar="SCENE", default=None,
                   help="developers: compute the display's idle policy of these shipped "
                        "scenes and write it into the package (scenes/NAME.idle.json)")
    p.set_defaults(func=cmd_scenes)


def add_dataset(sub) -> None:
    ds = sub.add_parser("dataset", help="generate, show or validate datasets")
    dsub = ds.add_subparsers(dest="dataset_command", required=True)
    p = dsub.add_parser("generate", help="write a scene's databases (pad/ and finger/)")
    p.add_argument("--scene", required=True, help="shipped scene name or TOML path")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--seed", type=_seed, default=0,
                   help="random seed of the sensors' errors and the trials (default 0)")
    p.add_argument("--force", action="store_true", help="replace a non-empty --out")
    p.set_defaults(func=cmd_dataset_generate)
    p = dsub.add_parser("show", help="plot a dataset (or a folder of datasets)")
    p.add_argument("dir", help="dataset folder (manifest.csv and its trial files)")
    p.add_argument("--out", required=True, help="PNG to write")
    p.set_defaults(func=cmd_dataset_show)
    p = dsub.add_parser("validate", help="read and check every file of a dataset")
    p.add_argument("dir", help="dataset folder (manifest.csv and its trial files)")
    p.set_defaults(func=cmd_dataset_validate)

    p = dsub.add_parser("import", help="add contacts to a dataset (identification database): "
                                       "MCAP recordings, or a lab's CSV files (one contact each; "
                                       "docs/concepts/databases.md, Dataset format)")
    p.add_argument("files", nargs="*", help="MCAP recordings or CSV files, told by content")
    p.add_argument("--into", required=True, help="dataset folder (created if absent)")
    p.add_argument("--material", help="the material touched (required for lab files)")
    p.add_argument("--group", help="what is held out together in cross-validation: a person, "
                                   "a session, an object (default for recordings: recorded)")
    p.add_argument("--manifest", help="CSV: file,material,group and, where known, T_object_C, "
                                      "T_pad_C, T_room_C, onset_s per lab file (relative to it); "
                                      "or another dataset's manifest.csv (its trials as they are)")
    p.add_argument("--scene", metavar="FILE|NAME",
                   help="the scene the recordings were made on, if a scene file (its room's "
                        "temperature; a shipped scene is found by the recorded name)")
    p.add_argument("--columns", help="dataset column=the file's column, comma-separated "
                                     "(t_s=time,heat_flux_W_m2=flux,temperature_C=T,force_N=F)")
    p.add_argument("--units", help="dataset column=unit: t_s s|ms, heat_flux_W_m2 "
                                   "W/m2|kW/m2|W/cm2, temperature_C C|K, force_N N|kN|gf")
    p.add_argument("--object-c", type=_temperature_c,
                   help="the object's temperature before contact (C)")
    p.add_argument("--pad-c", type=_temperature_c, help="the pad's measured temperature before "
                                               "contact (C; not its set point)")
    p.add_argument("--room-c", type=_temperature_c, help="the room's temperature (C)")
    p.add_argument("--onset-s", type=float, help="the contact's start on the file's clock (s); "
                                                 "default: t = 0 when the time goes below 0, "
                                                 "else the first force >= 1 N")
    p.set_defaults(func=cmd_dataset_import)


def add_simulate(sub) -> None:
    p = sub.add_parser("simulate", help="one contact between two semi-infinite bodies")
    p.add_argument("--pad", required=True, help="material of the pad (or finger: skin)")
    p.add_argument("--object", required=True, help="material of the object")
    p.add_argument("--pad-temp-c", type=_temperature_c, required=True,
                   help="the pad's (or finger's) temperature before contact, C")
    p.add_argument("--object-temp-c", type=_temperature_c, required=True,
                   help="the object's temperature before contact, C")
    p.add_argument("--seconds", type=_positive(at_most=CONTACT_MAX_S, why=CONTACT_WHY),
                   required=True, help="contact time to simulate, seconds (up to 600)")
    p.add_argument("--rate-hz", type=_positive(at_most=100000.0, why="the samples of a "
                                               "10-minute trial held in memory"),
                   required=True,
                   help="sample rate of the written trial, Hz")
    p.add_argument("--out", required=True, help="output dataset folder")
    p.add_argument("--ideal", action="store_true",
                   help="perfect contact, no sensor, no noise: the closed form")
    p.add_argument("--contact-conductance-w-m2k", type=_positive(), default=3000.0,
                   help="pad-object contact conductance, W/(m^2 K) (default 3000)")
    p.add_argument("--seed", type=_seed, default=0,
                   help="random seed of the sensors' noise (default 0)")
    p.add_argument("--force", action="store_true", help="replace a non-empty --out")
    p.set_defaults(func=cmd_simulate)
