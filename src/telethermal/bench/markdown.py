"""The benches' one renderer: every bench's section is Markdown written
from its JSON (the ``section(d, page)`` functions that
:data:`telethermal.bench.report.SECTIONS` lists). ``telethermal bench
report`` gathers the sections into ``bench/report.md``; each ``telethermal
bench NAME`` prints its own section in the terminal through rich's Markdown
renderer (:func:`terminal`). So what a bench prints and what the page says
are the same lines, written once."""

from __future__ import annotations

import io
import os
from dataclasses import dataclass
from pathlib import Path

from telethermal.bench.options import reduced_options


@dataclass(frozen=True)
class Page:
    """Where a section is written: the folder its figure links are relative
    to (``out``), the folder the bench's JSON and PNGs lie in
    (``results``), and whether a missing figure may be drawn into ``out``
    (the report does; a bench's printout writes nothing)."""

    out: Path
    results: Path
    draw: bool = True


def pct(x, digits: int = 2) -> str:
    """A fraction as a percentage (``-`` for none)."""
    return "-" if x is None else f"{100 * x:.{digits}f} %"


def num(x, digits: int = 3) -> str:
    """A number to ``digits`` significant figures (``-`` for none)."""
    return "-" if x is None else f"{x:.{digits}g}"


def table(header: list[str], rows: list[list]) -> list[str]:
    """A Markdown table, then an empty line."""
    return (["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
            + ["| " + " | ".join(str(c) for c in row) + " |" for row in rows] + [""])


def provenance(d: dict) -> str:
    """Under every section: the machine, the date, the command, and whether
    the run was reduced from the bench's defaults."""
    reduced = reduced_options(d.get("command", ""))
    note = "" if not reduced else (
        f" **Reduced run** (`{' '.join(reduced)}`): fewer methods, seeds, trials, rounds or "
        "settings than the bench's defaults, so its figures are not those of the committed "
        "run (`make bench-full`, every bench at its defaults).")
    return (f"*Machine {d.get('machine', '?')}; {d.get('date', '?')}; "
            f"`{d.get('command', '?')}`.*{note}")


def bench_png(page: Page, d: dict, name: str, suffix: str = "") -> Path | None:
    """Where the bench wrote its figure ``<name><suffix>.png``: beside its
    JSON (the default of every bench's ``--png``), else beside the path its
    JSON names (``faults`` writes ``<stem>-traces.png`` next to its PNG), if
    either is there."""
    beside = Path(page.results) / f"{name}{suffix}.png"
    if beside.is_file():
        return beside
    if not d.get("png"):
        return None
    named = Path(d["png"])
    named = named.with_name(f"{named.stem}{suffix}{named.suffix}")
    return named if named.is_file() else None


def link(page: Page, png: Path | str, alt: str) -> str:
    """A Markdown image of ``png`` as it lies, relative to ``page.out``."""
    rel = os.path.relpath(Path(png).resolve(), Path(page.out).resolve())
    return f"![{alt}]({Path(rel).as_posix()})\n"


def figure(page: Page, d: dict, name: str, suffix: str = "") -> str:
    """The bench's own PNG, linked where the bench wrote it ("" if none)."""
    png = bench_png(page, d, name, suffix)
    return "" if png is None else link(page, png, name + suffix)


def save(page: Page, fig, filename: str) -> str:
    """Draw ``fig`` into ``page.out/filename`` (atomically) and link it; ""
    on a page that draws nothing (the figure is closed either way)."""
    import matplotlib.pyplot as plt

    if not page.draw:
        plt.close(fig)
        return ""
    fig.tight_layout()
    path = Path(page.out) / filename
    tmp = path.with_name(f".{path.name}.tmp")
    fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    os.replace(tmp, path)
    return link(page, path, Path(filename).stem)


def terminal(lines: list[str], width: int | None = None) -> str:
    """Markdown ``lines`` as a terminal shows them (rich's renderer: tables
    drawn in columns, emphasis as styles on a terminal, plain text in a
    pipe), trailing spaces removed."""
    from rich.console import Console
    from rich.markdown import Markdown

    buf = io.StringIO()
    tty = os.isatty(1)
    console = Console(file=buf, width=width or (os.get_terminal_size().columns if tty else 120),
                      force_terminal=tty, color_system="auto" if tty else None,
                      highlight=False)
    console.print(Markdown("\n".join(lines), hyperlinks=False))
    return "\n".join(line.rstrip() for line in buf.getvalue().splitlines()).strip("\n")
