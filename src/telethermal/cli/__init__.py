"""The ``telethermal`` command."""

from __future__ import annotations

import argparse
import logging
import os
import sys
from pathlib import Path

from rich.markup import escape

from telethermal import __version__
from telethermal.cli import bench, calibrate, data, identify, operate, run, services, view
from telethermal.cli._common import console
from telethermal.errors import TelethermalError


#: What ``telethermal --help`` says the tool is.
DESCRIPTION = """\
telethermal: thermal telepresence. An operator touches a Peltier display (the
master) and feels what touching a remote object would feel like: a sensing pad
(the slave) touches the object, identifies its material from the first fraction
of a second of heat flux, and sends the flux the operator's finger would exchange
with it. A physics simulator stands in for the pads, the finger and the objects.

Start with `telethermal demo` (a whole session on two processes); each command
below has its own --help. Heat flux is positive from the pad into the object."""


def build_parser() -> argparse.ArgumentParser:
    """Every command, each group's from its module (in the order ``--help``
    lists them)."""
    parser = argparse.ArgumentParser(prog="telethermal", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"telethermal {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log at INFO level")
    sub = parser.add_subparsers(dest="command", required=True)
    data.add_scenes(sub)
    data.add_dataset(sub)
    services.add_peltier_emulator(sub)
    run.add_replay(sub)
    data.add_simulate(sub)
    bench.add_parser(sub)
    identify.add_parser(sub)
    calibrate.add_parser(sub)
    run.add_session(sub)
    services.add_parsers(sub)                # slave, master, faults, keys
    operate.add_parsers(sub)                 # admin, check, models
    run.add_demo(sub)
    view.add_parser(sub)
    return parser


def _check_json_path(args) -> None:
    """A command's ``--json`` report path that is a folder, refused before
    the command does any work (a bench had run to its end first)."""
    path = getattr(args, "json", None)
    if isinstance(path, str) and path and Path(path).is_dir():
        from telethermal.errors import UsageError
        raise UsageError(f"--json {path}: a folder; give the report's file, e.g. "
                         f"{Path(path) / 'report.json'}")


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    service = args.command in ("slave", "master")
    logging.basicConfig(level=logging.INFO if args.verbose or service else logging.WARNING,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s" if service
                        else "%(levelname)s %(name)s: %(message)s")
    try:
        _check_json_path(args)
        return args.func(args)
    except TelethermalError as exc:
        # escape: the text is the error's, not markup ("[pad]" is a TOML
        # section a message names, which rich would swallow as a tag).
        # soft_wrap: no line breaks of rich's inside it (a path cut in two
        # cannot be copied); the terminal wraps the line.
        console.print(f"[red]error:[/red] {escape(str(exc))}", highlight=False, soft_wrap=True)
        return 2
    except KeyboardInterrupt:
        console.print("interrupted")
        return 130
    except BrokenPipeError:
        # The reader of our output went away (``telethermal ... | head``):
        # nothing more to say, and nothing to say it to. Python's own
        # recipe: point stdout at devnull so the interpreter's final flush
        # does not raise again.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1
    except OSError as exc:
        # A path the command could not use (a folder given for a file, a
        # file for a folder, no permission): named with the system's reason,
        # not a traceback. The writers leave no part of a file behind.
        if exc.filename is None or args.verbose:          # -v: the traceback, for a bug
            raise
        where = str(exc.filename) + (f" -> {exc.filename2}" if exc.filename2 else "")
        console.print(f"[red]error:[/red] {escape(where)}: {escape(exc.strerror or str(exc))}",
                      highlight=False, soft_wrap=True)
        return 2

