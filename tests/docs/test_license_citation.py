"""LICENSE and CITATION.cff agree with pyproject.toml; the citation names
both papers, and the README and the concepts page cite them in full."""

from __future__ import annotations

import tomllib
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]


def test_license_file_is_the_license_pyproject_declares():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["license"] == "MIT"
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License") and "WITHOUT WARRANTY OF ANY KIND" in text


def test_citation_file_matches_the_project_and_cites_both_papers():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert cff["cff-version"] == "1.2.0" and cff["type"] == "software"
    assert cff["version"] == project["version"] and cff["license"] == project["license"]
    titles = {r["title"]: r for r in cff["references"]}
    assert set(titles) == {"Learning-Based Thermal Rendering in Telepresence",
                           "Active Heat Flow Sensing for Robust Material Identification"}
    for ref in titles.values():
        assert ref["authors"] and ref["year"], ref["title"]
    # The papers as the project holds them: the titles are theirs.
    for title in titles:
        assert title in (ROOT / "README.md").read_text().replace("\n  ", " ")
        assert title in (ROOT / "docs" / "concepts" / "index.md").read_text().replace("\n  ", " ")
