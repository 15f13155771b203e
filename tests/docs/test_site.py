"""The docs site builds with warnings as errors (MkDocs, strict), every page
is in the navigation, and no internal link or image in the built site points
at nothing.

Skipped when MkDocs is not installed (the ``docs`` extra), unless
``TELETHERMAL_REQUIRE_DOCS=1`` (as ``.ci/run`` sets): then it fails.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

ROOT = Path(__file__).resolve().parents[2]
REQUIRE = os.environ.get("TELETHERMAL_REQUIRE_DOCS") == "1"


def _need_mkdocs() -> None:
    missing = [m for m in ("mkdocs", "material", "mkdocstrings_handlers.python")
               if importlib.util.find_spec(m.split(".")[0]) is None]
    if missing:
        why = f"the docs extra is not installed (missing: {', '.join(missing)}): pip install '.[docs]'"
        if REQUIRE:
            pytest.fail(why)
        pytest.skip(why)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    _need_mkdocs()
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    r = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
                       cwd=ROOT, capture_output=True, text=True, env=env)
    warnings = [line for line in r.stderr.splitlines() if "WARNING" in line or "ERROR" in line]
    assert r.returncode == 0 and not warnings, \
        "mkdocs build --strict failed:\n" + "\n".join(warnings or r.stderr.splitlines()[-20:])
    return out


def _nav_pages(nav) -> list[str]:
    pages = []
    for item in nav:
        if isinstance(item, str):
            pages.append(item)
        elif isinstance(item, dict):
            for value in item.values():
                pages += _nav_pages(value) if isinstance(value, list) else [value]
    return pages


def test_every_page_is_in_the_navigation(site):
    import yaml
    config = yaml.load((ROOT / "mkdocs.yml").read_text(), Loader=yaml.BaseLoader)
    nav = set(_nav_pages(config["nav"]))
    docs = {p.relative_to(ROOT / "docs").as_posix() for p in (ROOT / "docs").rglob("*.md")}
    assert docs - nav == set(), f"pages under docs/ missing from mkdocs.yml's nav: {sorted(docs - nav)}"
    for page in nav:                                       # and each one built
        assert (site / page).with_suffix(".html").is_file(), page


class _Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.refs: list[str] = []
        self.ids: set[str] = set()

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if attrs.get("id"):
            self.ids.add(attrs["id"])
        for key in ("href", "src"):
            if attrs.get(key):
                self.refs.append(attrs[key])


def _parse(page: Path) -> _Links:
    links = _Links()
    links.feed(page.read_text(encoding="utf-8"))
    return links


def broken_links(site: Path) -> list[str]:
    """Every internal href/src of the built site whose file, or whose
    #anchor in that file, does not exist: "page -> target"."""
    parsed = {page: _parse(page) for page in site.rglob("*.html")}
    broken = []
    for page, links in parsed.items():
        for ref in links.refs:
            parts = urlsplit(ref)
            if parts.scheme or parts.netloc or ref.startswith(("mailto:", "javascript:")):
                continue
            path = unquote(parts.path)
            base = site if path.startswith("/") else page.parent      # 404.html: from the root
            target = (base / path.lstrip("/")).resolve() if path else page
            if target.is_dir():
                target = target / "index.html"
            if not target.exists():
                broken.append(f"{page.relative_to(site)} -> {ref}")
            elif parts.fragment and target.suffix == ".html":
                ids = parsed[target].ids if target in parsed else _parse(target).ids
                if unquote(parts.fragment) not in ids:
                    broken.append(f"{page.relative_to(site)} -> {ref} (no such anchor)")
    return broken


def test_no_broken_internal_link(site):
    broken = broken_links(site)
    assert broken == [], f"{len(broken)} broken internal links:\n" + "\n".join(broken)


def test_the_link_check_finds_a_broken_link(site, tmp_path):
    # The check above cannot pass by finding nothing: a page with one link to
    # a missing page and one to a missing anchor gives exactly those two.
    (tmp_path / "a.html").write_text('<a href="b.html">b</a> <a href="a.html#nowhere">x</a> '
                                     '<h2 id="here">h</h2> <a href="#here">ok</a>')
    assert broken_links(tmp_path) == ["a.html -> b.html", "a.html -> a.html#nowhere (no such anchor)"]
    assert len(list(site.rglob("*.html"))) >= 20
