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
from itertools import zip_longest
from dataclasses import dataclass
from pathlib import Path

from telethermal.bench.options import off_defaults


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


def val(x, spec: str = ".2f", unit: str = "") -> str:
    """``x`` formatted with ``spec`` and its unit (``-`` for none: a figure
    an older or smaller run did not write)."""
    return "-" if x is None else f"{x:{spec}}{unit}"


def table(header: list[str], rows: list[list]) -> list[str]:
    """A Markdown table, then an empty line."""
    return (["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
            + ["| " + " | ".join(str(c) for c in row) + " |" for row in rows] + [""])


def provenance(d: dict) -> str:
    """Under every section: the machine, the date, the command, and whether
    the run was reduced from the bench's defaults."""
    reduced, settings = off_defaults(d.get("command", ""))
    note = "" if not reduced else (
        f" **Reduced run** (`{' '.join(reduced)}`): fewer methods, seeds, trials, rounds or "
        "settings than the bench's defaults, so its figures are not those of the committed "
        "run (`make bench-full`, every bench at its defaults).")
    if settings:
        note += (f" **Another setting** (`{' '.join(settings)}`): a comparison beside the "
                 "bench's default run, not its committed figures.")
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


def table_width(lines: list[str]) -> int:
    """The console width on which rich draws every table of ``lines`` on
    one line per row (rich squeezes a table too wide for its console, and
    cuts the words that still do not fit): per column its longest cell over
    the table's rows, plus the padding and rules rich puts around cells."""
    from rich.cells import cell_len           # a wide character takes two columns

    widest, cols = 0, []
    for line in [*lines, ""]:
        if line.startswith("|") and line.endswith("|"):
            if set(line) <= set("|-: "):               # the header's rule
                continue
            cells = [c.strip() for c in line.strip("|").split("|")]
            words = [max(cell_len(c), 1) for c in cells]
            cols = [max(a, b) for a, b in zip_longest(cols, words, fillvalue=0)]
        elif cols:                                       # a table ended
            widest = max(widest, sum(w + 3 for w in cols) + 1)
            cols = []
    return widest


def _blocks(lines: list[str]) -> list[tuple[bool, list[str]]]:
    """``lines`` cut into runs: (True, a table's lines) or (False, the rest;
    a fenced block's lines are never a table's)."""
    out: list[tuple[bool, list[str]]] = []
    fenced = False
    for line in lines:
        if line.startswith("```"):
            fenced = not fenced
        is_table = not fenced and line.startswith("|") and line.endswith("|")
        if out and out[-1][0] == is_table:
            out[-1][1].append(line)
        else:
            out.append((is_table, [line]))
    return out


def terminal(lines: list[str], width: int | None = None) -> str:
    """Markdown ``lines`` as a terminal shows them (rich's renderer: tables
    drawn in columns, emphasis as styles on a terminal, plain text in a
    pipe), trailing spaces removed. Text wraps at ``width`` (the terminal's;
    120 in a pipe); a table is drawn as wide as its rows need
    (:func:`table_width`): a long row, never a cell cut short."""
    from rich.console import Console
    from rich.markdown import Markdown

    tty = os.isatty(1)
    width = width or (os.get_terminal_size().columns if tty else 120)
    out = []
    for is_table, block in _blocks(lines):
        buf = io.StringIO()
        console = Console(file=buf, width=max(width, table_width(block)) if is_table else width,
                          force_terminal=tty, color_system="auto" if tty else None,
                          highlight=False)
        console.print(Markdown("\n".join(block), hyperlinks=False))
        out.append("\n".join(line.rstrip() for line in buf.getvalue().splitlines()).strip("\n"))
    return "\n\n".join(o for o in out if o)
