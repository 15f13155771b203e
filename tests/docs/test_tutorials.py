"""The tutorials run as written: every command block of "Getting started"
and "Your own pad", in the page's order, in an empty folder; the files those
pages show under a name are written there first; the page's Python example
runs as a doctest. A command that no longer runs, or an example whose output
changed, fails here with the page and the line."""

from __future__ import annotations

import doctest
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = ["getting-started.md", "own-pad.md"]
FENCE = re.compile(r"^```(\w+)(?:[ \t]+title=\"([^\"]+)\")?[ \t]*\n(.*?)^```[ \t]*$", re.M | re.S)


def blocks(page: Path) -> list[tuple[str, str | None, str, int]]:
    """(language, title, body, line) of every fenced block, in order."""
    text = page.read_text()
    return [(m.group(1), m.group(2), m.group(3), text.count("\n", 0, m.start()) + 1)
            for m in FENCE.finditer(text)]


def _env() -> dict[str, str]:
    src = str(ROOT / "src")
    path = os.environ.get("PYTHONPATH")
    return {**os.environ, "PYTHONPATH": src if not path else f"{src}{os.pathsep}{path}",
            "NO_COLOR": "1"}


def _run(command: str, cwd: Path, where: str) -> None:
    argv = shlex.split(command)
    assert argv[0] == "telethermal", f"{where}: a console block runs telethermal, not {argv[0]!r}"
    r = subprocess.run([sys.executable, "-m", "telethermal", *argv[1:]], cwd=cwd, env=_env(),
                       capture_output=True, text=True, timeout=1800)
    assert r.returncode == 0, (f"{where}: `{command}` exited {r.returncode}\n"
                               f"{r.stdout[-3000:]}\n{r.stderr[-3000:]}")


def _doctest(body: str, cwd: Path, where: str, monkeypatch) -> None:
    monkeypatch.chdir(cwd)
    test = doctest.DocTestParser().get_doctest(body, {}, where, where, 0)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    out: list[str] = []
    runner.run(test, out=out.append)
    assert runner.failures == 0, "".join(out)
    assert runner.tries >= 5, f"{where}: the example has {runner.tries} lines to check"


@pytest.mark.slow
@pytest.mark.parametrize("name", PAGES)
def test_every_block_of_the_page_runs(name, tmp_path, monkeypatch):
    page = ROOT / "docs" / name
    ran = 0
    for lang, title, body, line in blocks(page):
        where = f"docs/{name}:{line}"
        if title:
            target = tmp_path / title
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(body)
        elif lang == "console":
            commands = [ln[2:] for ln in body.splitlines() if ln.startswith("$ ")]
            assert commands, f"{where}: a console block without a `$ ` command"
            for command in commands:
                _run(command, tmp_path, where)
                ran += 1
        elif lang == "pycon":
            _doctest(body, tmp_path, where, monkeypatch)
            ran += 1
        elif lang == "sh":
            _make_targets(body, where)
            ran += 1
        else:
            pytest.fail(f"{where}: a ```{lang} block neither runs nor is a named file: "
                        "console ($ lines), pycon, sh (make targets) or title=\"FILE\"")
    assert ran >= 3, f"docs/{name}: only {ran} blocks ran"
    if name == "getting-started.md":
        missing = [f for f in demo_files_named(page.read_text()) if not list((tmp_path / "demo").glob(f))]
        assert missing == [], f"docs/{name}: the demo wrote none of {missing}"


def demo_files_named(text: str) -> list[str]:
    """The files "What the demo writes" names (`touch-<material>.png` as a
    glob), each a pattern under the demo's folder."""
    section = text[text.index("## What the demo writes"):]
    section = section[:section.index("\n## ", 1)]
    names = re.findall(r"`([\w<>./-]+(?:\.\w+|/))`", section)
    return sorted({re.sub(r"<\w+>", "*", n).rstrip("/") for n in names
                   if n not in ("demo/", "out/demo/") and ("." in n or n.endswith("/"))})


def _make_targets(body: str, where: str) -> None:
    """A ```sh block holds `make TARGET` lines: each target is the
    Makefile's, and its dry run (make -n: nothing executed) succeeds."""
    targets = [ln.split()[1] for ln in body.splitlines() if ln.startswith("make ")]
    assert targets, f"{where}: an sh block without a make target"
    r = subprocess.run(["make", "-n", "-C", str(ROOT), *targets], capture_output=True, text=True)
    assert r.returncode == 0, f"{where}: make -n {' '.join(targets)}: {r.stderr}"


def test_the_demo_files_the_page_names_are_read_as_patterns():
    text = (ROOT / "docs" / "getting-started.md").read_text()
    names = demo_files_named(text)
    assert {"demo.json", "databases", "touch-*.png", "identifier.npz", "keys"} <= set(names)


def test_the_block_reader_sees_titles_and_languages(tmp_path):
    page = tmp_path / "p.md"
    page.write_text('x\n```toml title="a/b.toml"\nk = 1\n```\n\n```console\n$ telethermal scenes\n```\n')
    assert blocks(page) == [("toml", "a/b.toml", "k = 1\n", 2), ("console", None,
                                                                "$ telethermal scenes\n", 6)]
