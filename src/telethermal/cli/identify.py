"""``telethermal identify methods|train|eval|cv``."""

from __future__ import annotations

import argparse

from telethermal.cli._common import _command, _png, _positive, _print_lines, console, log


def _channels(text: str) -> tuple[str, ...]:
    names = tuple(c.strip() for c in text.split(",") if c.strip())
    if not names:
        raise argparse.ArgumentTypeError("give at least one channel")
    return names


def cmd_identify_methods(args) -> int:
    from telethermal.ident.registry import METHODS

    for name, cls in sorted(METHODS.items()):
        print(f"{name:16s} {cls.__doc__.strip().splitlines()[0]}")
    return 0


def cmd_identify_train(args) -> int:
    from telethermal.ident.registry import train_on_dataset

    trained = train_on_dataset(args.data, args.method, args.channels, args.max_window_s,
                               args.out, status=console.status, logger=log,
                               unseen_weight=args.unseen_weight)
    model = trained.model
    print(f"{trained.path}: {args.method} on {', '.join(model.classes_)}; "
          f"{len(model.windows_s_)} windows up to {model.windows_s_[-1]} s; "
          f"trained in {trained.train_s:.1f} s")
    return 0


def cmd_identify_eval(args) -> int:
    from telethermal.ident.evaluate import evaluate_saved, text_report

    png = _png(args)
    report = evaluate_saved(args.model, args.data, args.json, png, command=_command(),
                            status=console.status)
    _print_lines(text_report(report, args.json, png))
    return 0


def cmd_identify_cv(args) -> int:
    from telethermal.data.dataset import load_dataset
    from telethermal.ident.crossval import cross_validate, text_report
    from telethermal.jsonfile import write_json

    with console.status(f"reading {args.data}"):
        trials = load_dataset(args.data)
    with console.status("cross-validating") as status:
        report = cross_validate(trials, args.method, args.folds, args.channels,
                                args.max_window_s, progress=status.update)
    report["data"], report["command"] = str(args.data), _command()
    if args.json:
        write_json(args.json, report)
    _print_lines(text_report(report, args.json))
    return 0


def add_parser(sub) -> None:
    ident = sub.add_parser("identify", help="material identification")
    isub = ident.add_subparsers(dest="identify_command", required=True)
    p = isub.add_parser("methods", help="list the identification methods")
    p.set_defaults(func=cmd_identify_methods)
    p = isub.add_parser("train", help="fit an identifier on a dataset")
    p.add_argument("--data", required=True, help="dataset folder")
    p.add_argument("--method", required=True)
    p.add_argument("--channels", type=_channels, default=("heat_flux_W_m2",),
                   help="comma-separated channels (default heat_flux_W_m2)")
    p.add_argument("--max-window-s", type=_positive(), default=1.0)
    p.add_argument("--out", required=True, help="model file to write (.npz)")
    p.add_argument("--unseen-weight", type=float, default=None, metavar="W",
                   help="effusivity-fit: the prior weight of a material outside the classes "
                        "against one class's (default 0: a closed set; 1: as likely as each; "
                        "bench unseen shows the trade)")
    p.set_defaults(func=cmd_identify_train)
    p = isub.add_parser("eval", help="score a model on a dataset")
    p.add_argument("--model", required=True)
    p.add_argument("--data", required=True)
    p.add_argument("--json", required=True)
    p.add_argument("--png")
    p.set_defaults(func=cmd_identify_eval)
    p = isub.add_parser("cv", help="grouped k-fold cross-validation of a method on a dataset: "
                                   "accuracy per window with 95 %% intervals, the decisions "
                                   "(commit rate, accuracy, named alone, confusion), calibration")
    p.add_argument("--data", required=True, help="dataset folder")
    p.add_argument("--method", required=True)
    p.add_argument("--folds", type=int, default=5,
                   help="folds; each holds whole groups (default 5)")
    p.add_argument("--channels", type=_channels, default=("heat_flux_W_m2",),
                   help="comma-separated channels (default heat_flux_W_m2)")
    p.add_argument("--max-window-s", type=_positive(), default=1.0)
    p.add_argument("--json", help="write the report here")
    p.set_defaults(func=cmd_identify_cv)
