"""Measurements live in bench/results/ and the benchmark page, dated there
only: README.md, the Makefile, the user guide's pages (bar the changelog)
and the comments and docstrings of src/ say
what things do, not when or on which machine they were timed. A date
(2026-11-27), or a "measured ... on <date or machine>" note, fails here with
its file and line."""

from __future__ import annotations

import ast
import io
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DATE = re.compile(r"\b(?:19|20)\d\d-(?:0[1-9]|1[0-2])-(?:0[1-9]|[12]\d|3[01])\b")
MEASURED_ON = re.compile(r"\bmeasured\b[^.;\n]{0,80}?\bon\s+(?:(?:19|20)\d\d\b|\d{1,2}\s+[A-Z][a-z]+"
                         r"|this\s+(?:\S+\s+){0,2}(?:machine|VM|vm|laptop|host)\b"
                         r"|the\s+\d+-core\b)", re.I)

#: Dated notes known and not yet moved, by file and count, so that none is
#: skipped unseen: each must still be there (the test below fails once it is
#: gone, so the entry goes too) and is the only finding allowed in its file.
#: Empty: every note has moved to bench/results/ or the changelog.
PENDING: dict[str, int] = {}


def findings(text: str) -> list[tuple[int, str]]:
    """(line offset in ``text``, wording) of every date or "measured ... on"
    note in ``text``."""
    return [(text.count("\n", 0, m.start()), m.group(0))
            for rx in (DATE, MEASURED_ON) for m in rx.finditer(text)]


def _python_notes(path: Path) -> list[tuple[int, str]]:
    """(line, text) of every comment and docstring of a Python file."""
    src = path.read_text(encoding="utf-8")
    notes = [(tok.start[0], tok.string) for tok in tokenize.generate_tokens(io.StringIO(src).readline)
             if tok.type == tokenize.COMMENT]
    for node in ast.walk(ast.parse(src)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node, clean=False)
            if doc:
                notes.append((node.body[0].lineno, doc))
    # Attribute docstrings (``#:`` comments are comments; a bare string after
    # an assignment is read as one too).
    return notes


#: The user guide too, bar the changelog (the project's history, dated by
#: nature) and the benchmark page (bench/report.md, not under docs/).
DOC_PAGES = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").rglob("*.md")
                   if p.name != "changelog.md")


def dated_notes() -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for name in ("README.md", "Makefile", *DOC_PAGES):
        for n, line in enumerate((ROOT / name).read_text(encoding="utf-8").splitlines(), 1):
            for _, f in findings(line):
                out.setdefault(name, []).append(f"{name}:{n}: {f}")
    for path in sorted((ROOT / "src").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        for line, text in _python_notes(path):
            for offset, f in findings(text):
                out.setdefault(rel, []).append(f"{rel}:{line + offset}: {f}")
    return out


def test_no_dated_measurement_in_readme_makefile_or_source_comments():
    found = dated_notes()
    unexpected = [f for rel, fs in found.items() if rel not in PENDING for f in fs]
    unexpected += [f"{rel}: {len(found[rel])} findings, {PENDING[rel]} known: {found[rel]}"
                   for rel in PENDING if rel in found and len(found[rel]) > PENDING[rel]]
    assert unexpected == [], ("dated measurements belong in bench/results/ and the benchmark "
                              "page:\n" + "\n".join(unexpected))


@pytest.mark.parametrize("rel", sorted(PENDING))
def test_each_pending_note_is_still_there(rel):
    found = dated_notes().get(rel, [])
    assert found, f"{rel} has no dated note left: remove it from PENDING"


@pytest.mark.parametrize("text, hits", [
    ("run on 2026-11-27 05:41", ["2026-11-27"]),
    ("measured 26 minutes on 2026-11-27", ["2026-11-27", "measured 26 minutes on 2026"]),
    ("# 1.2 ms, measured on this 2-core machine", ["measured on this 2-core machine"]),
    ("No Chromium on this machine", []),
    ("the measured flux, positive into the object", []),
    ("ISO 13732-1: 43 C", []),
])
def test_the_patterns_find_dates_and_notes_and_nothing_else(text, hits):
    assert [f for _, f in findings(text)] == hits


def test_the_readme_is_a_front_page_whose_links_resolve():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.splitlines()) <= 150
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", readme)
    assert len(targets) >= 10
    broken = [t for t in targets if "://" not in t and not (ROOT / t).exists()]
    assert broken == [], f"README links to missing files: {broken}"
