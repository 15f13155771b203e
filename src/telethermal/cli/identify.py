"""``telethermal identify methods|train|eval|cv``."""

from __future__ import annotations

import argparse
import inspect
import re
import sys
import textwrap

from telethermal.cli._common import _command, _png, _positive, _print_lines, console, log


def _channels(text: str) -> tuple[str, ...]:
    names = tuple(c.strip() for c in text.split(",") if c.strip())
    if not names:
        raise argparse.ArgumentTypeError("give at least one channel")
    return names


def method_description(cls) -> str:
    """The first paragraph of an identifier's docstring, whole, on one line;
    where it refers to its module, the module's first paragraph after its
    title as well."""
    paragraph = inspect.cleandoc(cls.__doc__ or "").split("\n\n")[0]
    if "see the module" in paragraph:
        module = inspect.cleandoc(sys.modules[cls.__module__].__doc__ or "").split("\n\n")
        paragraph = paragraph.replace(" (see the module)", "") + " " + " ".join(module[1:2])
    text = re.sub(r":\w+:`~?(?:\w+\.)*(\w+)`", r"\1", " ".join(paragraph.split()))
    return text.replace("``", "`")


def cmd_identify_methods(args) -> int:
    from telethermal.ident.registry import METHODS
    from telethermal.teleop.models import DEFAULT_METHOD, FALLBACK_METHOD

    marks = {DEFAULT_METHOD: "[default] ",
             FALLBACK_METHOD: f"[default where {DEFAULT_METHOD} cannot model the scene] "}
    for name, cls in sorted(METHODS.items()):
        text = textwrap.fill(marks.get(name, "") + method_description(cls), width=88,
                             initial_indent="  ", subsequent_indent="  ")
        print(f"{name}\n{text}\n")
    return 0


def _scene(args):
    """``--scene`` loaded (a shipped name or a scene file) and given to this
    process's pad models by its name; None when not given."""
    if not getattr(args, "scene", None):
        return None
    from telethermal.ident.fitted import register_scene
    from telethermal.physics.scene import load_scene
    scene = load_scene(args.scene)
    register_scene(scene)
    return scene


def _calibration(args, scene):
    """``--calibration CAL.toml`` read and checked against the touches' scene
    (a Scene or a name); None when not given."""
    if not getattr(args, "calibration", None):
        return None
    from telethermal.errors import CalibrationError
    from telethermal.ident.fitted import scene_of
    from telethermal.ident.pad_calibration import read_calibration
    cal = read_calibration(args.calibration)
    if scene is None:
        raise CalibrationError(f"--calibration {args.calibration}: the touches name no scene; "
                               "give --scene, the scene whose pad it calibrates")
    cal.check(scene_of(scene) if isinstance(scene, str) else scene)
    return cal


def _method(args, scene) -> str:
    """``--method``, else the slave's own for the touches' scene (effusivity-fit
    where it can model the scene's pad, else effusivity-lda; said why)."""
    if args.method:
        return args.method
    from telethermal.ident.fitted import scene_of
    from telethermal.ident.registry import dataset_scene, pad_dataset
    from telethermal.teleop.models import FALLBACK_METHOD, method_and_reason
    scene = scene or dataset_scene(pad_dataset(args.data))
    if scene is None:
        method, why = FALLBACK_METHOD, "the dataset names no scene (give --scene)"
    else:
        method, why = method_and_reason(scene_of(scene) if isinstance(scene, str) else scene)
    print(f"method {method}: {why}")
    return method


def cmd_identify_train(args) -> int:
    from telethermal.ident.registry import train_on_dataset

    scene = _scene(args)
    args.method = _method(args, scene)
    from telethermal.ident.registry import dataset_scene, pad_dataset
    cal = _calibration(args, scene or dataset_scene(pad_dataset(args.data)))
    trained = train_on_dataset(args.data, args.method, args.channels, args.max_window_s,
                               args.out, status=console.status, logger=log,
                               unseen_weight=args.unseen_weight, scene=scene, calibration=cal)
    model = trained.model
    print(f"{trained.path}: {args.method} on {', '.join(model.classes_)}; "
          f"{len(model.windows_s_)} windows up to {model.windows_s_[-1]} s; "
          f"trained in {trained.train_s:.1f} s")
    return 0


def cmd_identify_eval(args) -> int:
    from telethermal.ident.evaluate import evaluate_saved, text_report

    png = _png(args)
    scene = _scene(args)
    if getattr(args, "calibration", None):
        from telethermal.errors import ModelFileError
        from telethermal.ident.pad_calibration import read_calibration
        from telethermal.ident.registry import load_model
        trained = getattr(load_model(args.model), "calibration", None)
        if trained is None or trained.to_dict() != read_calibration(args.calibration).to_dict():
            raise ModelFileError(f"{args.model} was trained with "
                                 f"{'no pad calibration' if trained is None else 'another'} "
                                 f"than {args.calibration}: train it with that calibration")
    report = evaluate_saved(args.model, args.data, args.json, png, command=_command(),
                            status=console.status, scene=scene)
    _print_lines(text_report(report, args.json, png))
    return 0


def cmd_identify_cv(args) -> int:
    from telethermal.data.dataset import load_dataset
    from telethermal.ident.crossval import cross_validate, text_report
    from telethermal.ident.registry import pad_dataset, touches_scene
    from telethermal.jsonfile import write_json

    scene = _scene(args)
    method = _method(args, scene)
    data = pad_dataset(args.data)
    touched = touches_scene(data, scene)
    with console.status(f"reading {data}"):
        trials = load_dataset(data)
    with console.status("cross-validating") as status:
        report = cross_validate(trials, method, args.folds, args.channels,
                                args.max_window_s, progress=status.update, scene=touched,
                                calibration=_calibration(args, touched))
    report["data"], report["command"] = str(args.data), _command()
    if args.json:
        write_json(args.json, report)
    _print_lines(text_report(report, args.json))
    return 0


DATA_HELP = "dataset folder (a generated one's pad/, or the folder holding pad/ and finger/)"
METHOD_HELP = ("identifier: see `telethermal identify methods` (default: the slave's own for "
               "the scene: effusivity-fit where it can model the pad, else effusivity-lda)")
SCENE_HELP = ("the scene whose pad made the touches: a shipped name or a scene file (default: "
              "the one the dataset's generation.json names)")


CAL_HELP = ("the pad's calibration (telethermal calibrate pad): effusivity-fit's pad model "
            "as calibrated, recorded in the model file")


def add_parser(sub) -> None:
    ident = sub.add_parser("identify", help="material identification")
    isub = ident.add_subparsers(dest="identify_command", required=True)
    p = isub.add_parser("methods", help="list the identification methods")
    p.set_defaults(func=cmd_identify_methods)
    p = isub.add_parser("train", help="fit an identifier on a dataset")
    p.add_argument("--data", required=True, help=DATA_HELP)
    p.add_argument("--method", help=METHOD_HELP)
    p.add_argument("--scene", help=SCENE_HELP)
    p.add_argument("--calibration", metavar="CAL.toml", help=CAL_HELP)
    p.add_argument("--channels", type=_channels, default=("heat_flux_W_m2",),
                   help="comma-separated channels (default heat_flux_W_m2)")
    p.add_argument("--max-window-s", type=_positive(), default=1.0,
                   help="longest window after contact the model learns, seconds (default 1)")
    p.add_argument("--out", required=True, help="model file to write (.npz)")
    p.add_argument("--unseen-weight", type=float, default=None, metavar="W",
                   help="effusivity-fit: the prior weight of a material outside the classes "
                        "against one class's (default 0: a closed set; 1: as likely as each; "
                        "bench unseen shows the trade)")
    p.set_defaults(func=cmd_identify_train)
    p = isub.add_parser("eval", help="score a model on a dataset")
    p.add_argument("--model", required=True, help="a model file from `identify train` (.npz)")
    p.add_argument("--data", required=True,
                   help="dataset folder to score the model on (held-out contacts)")
    p.add_argument("--json", required=True,
                   help="JSON report to write: accuracy per window, decisions, calibration")
    p.add_argument("--png", help="plot of accuracy against time after contact")
    p.add_argument("--scene", help=SCENE_HELP)
    p.add_argument("--calibration", metavar="CAL.toml", help=CAL_HELP)
    p.set_defaults(func=cmd_identify_eval)
    p = isub.add_parser("cv", help="grouped k-fold cross-validation of a method on a dataset: "
                                   "accuracy per window with 95 %% intervals, the decisions "
                                   "(commit rate, accuracy, named alone, confusion), calibration")
    p.add_argument("--data", required=True, help=DATA_HELP)
    p.add_argument("--method", help=METHOD_HELP)
    p.add_argument("--scene", help=SCENE_HELP)
    p.add_argument("--calibration", metavar="CAL.toml", help=CAL_HELP)
    p.add_argument("--folds", type=int, default=5,
                   help="folds; each holds whole groups (default 5)")
    p.add_argument("--channels", type=_channels, default=("heat_flux_W_m2",),
                   help="comma-separated channels (default heat_flux_W_m2)")
    p.add_argument("--max-window-s", type=_positive(), default=1.0,
                   help="longest window after contact the models learn, seconds (default 1)")
    p.add_argument("--json", help="write the report here")
    p.set_defaults(func=cmd_identify_cv)
