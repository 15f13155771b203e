"""What the command groups share: the console and logger, the progress bar,
the command line as typed, and the argument types."""

from __future__ import annotations

import argparse
import logging
import math
import sys
from contextlib import contextmanager
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

log = logging.getLogger("telethermal")
console = Console(stderr=True)


@contextmanager
def _progress(total: int, what: str):
    """A rich progress bar on stderr; ``advance(label)`` moves it on."""
    with Progress(SpinnerColumn(), TextColumn("{task.description}"), BarColumn(),
                  TextColumn("{task.completed}/{task.total}"), TimeElapsedColumn(),
                  console=console, transient=True, disable=not console.is_terminal) as bar:
        task = bar.add_task(what, total=total)

        def advance(label: str):
            bar.update(task, advance=1, description=f"{what}: {label}")
        yield advance


def _command() -> str:
    """The command line as typed, for the reports, absolute paths
    shortened to their file's name (:func:`portable_command`)."""
    return "telethermal " + " ".join(_portable_word(w) for w in sys.argv[1:])


def _portable_word(word: str) -> str:
    """An absolute path (``/...``, or ``--option=/...``) as its file's name."""
    key, eq, value = word.partition("=") if word.startswith("--") else ("", "", word)
    return key + eq + Path(value).name if value.startswith("/") else word


def portable_command(command: str) -> str:
    """A stored ``command`` with every absolute path shortened to its
    file's name (words split at spaces): a report kept in the project names
    no folder of the machine it was run on."""
    return " ".join(_portable_word(w) for w in command.split(" "))


def _png(args) -> Path:
    """``--png``, or the JSON's path with ``.png``; checked before any work
    (a folder, or a suffix matplotlib writes no figure as, refused by name)."""
    from matplotlib.figure import Figure

    from telethermal.errors import UsageError

    path = Path(args.png) if args.png else Path(args.json).with_suffix(".png")
    what = "--png" if args.png else "the figure beside --json,"
    if path.is_dir():
        raise UsageError(f"{what} {path}: a folder; give the figure's file, e.g. "
                         f"{path / 'figure.png'}")
    kinds = sorted(Figure().canvas.get_supported_filetypes())
    if path.suffix.lstrip(".").lower() not in kinds:
        raise UsageError(f"{what} {path}: no figure format ends so; matplotlib writes "
                         f"{', '.join('.' + k for k in kinds)}")
    return path


def _print_lines(lines: list[str]) -> None:
    for line in lines:
        print(line)


def _positive(kind=float, at_most: float | None = None, why: str = "",
              at_least: float | None = None, why_least: str = ""):
    """An argument type: a positive, finite ``kind``, no more than
    ``at_most`` and no less than ``at_least`` when given (``why``,
    ``why_least``: each bound's reason, said with it)."""
    def parse(text):
        try:
            value = kind(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from exc
        if not (value > 0 and math.isfinite(value)):
            raise argparse.ArgumentTypeError(f"{text!r} must be positive and finite")
        if at_most is not None and value > at_most:
            raise argparse.ArgumentTypeError(f"{text!r} is over {at_most:g}" +
                                             (f" ({why})" if why else ""))
        if at_least is not None and value < at_least:
            raise argparse.ArgumentTypeError(f"{text!r} is under {at_least:g}" +
                                             (f" ({why_least})" if why_least else ""))
        return value
    return parse


#: The longest touch a command simulates, s: a session's trace (every
#: period's row) is held in memory until it is written.
CONTACT_MAX_S = 600.0
CONTACT_WHY = "a touch of up to 10 minutes: its trace is held in memory"
#: The fastest display loop a session runs, Hz (the benches sweep 100-1000).
RATE_MAX_HZ = 10000.0
RATE_WHY = "the display loop's period must stay over 0.1 ms"


def _port(text):
    """An argument type: a TCP port, 1-65535, or 0 (a free one)."""
    try:
        value = int(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r} is not a port number") from exc
    from telethermal.ports import port_problem

    why = port_problem(value, "a free one")
    if why:
        raise argparse.ArgumentTypeError(f"{text!r}: {why}")
    return value


def _non_negative(text):
    """An argument type: a finite float >= 0."""
    value = _finite(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be >= 0")
    return value


def _wait_s(text):
    """An argument type: a wait in seconds, 0 (look once) to an hour."""
    value = _non_negative(text)
    if value > 3600:
        raise argparse.ArgumentTypeError(f"{text!r} is over 3600 s")
    return value


def _seed(text):
    """An argument type: a random seed, an integer >= 0 (numpy's generators
    take no negative seed)."""
    try:
        value = int(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from exc
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: a seed is a whole number >= 0")
    return value


def _temperature_c(text):
    """An argument type: a temperature in C, finite and above absolute zero."""
    value = _finite(text)
    if not value > -273.15:
        raise argparse.ArgumentTypeError(f"{text!r} C is below absolute zero (-273.15 C)")
    return value


def _finite(text):
    """An argument type: a finite float."""
    try:
        value = float(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from exc
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} must be finite")
    return value


def _models_folder(value: str) -> str:
    """``--models DIR`` of a bench, checked before the bench starts: its
    files there and matching their SHA256SUMS (the scene is checked when
    the bench has loaded its own)."""
    from telethermal.bench.models import checked_folder
    from telethermal.errors import BenchError
    try:
        checked_folder(value, f"`telethermal models --out {value}`")
    except BenchError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix(f"--models {value}: ")) from None
    return value
