"""bench report: every committed benchmark in one Markdown file, each
section stating machine, date and command, its figures written beside it."""

import re
import shutil
from pathlib import Path

from telethermal.bench.report import BY_HAND, SECTIONS, write_report

RESULTS = Path(__file__).parents[2] / "bench" / "results"


def test_the_report_has_every_section_with_its_provenance_and_figures(tmp_path):
    md = write_report(RESULTS, tmp_path / "report.md", "make bench")
    text = md.read_text()
    present = [name for name, _ in SECTIONS if (RESULTS / f"{name}.json").is_file()]
    assert len(present) == len(SECTIONS)          # every bench has committed results
    by_hand = [name for name, _ in BY_HAND if (RESULTS / f"{name}.json").is_file()]
    assert by_hand == ["skin-floor", "identify-as-built", "unseen-as-built",
                       "unseen-as-built-aluminium", "render-as-built"]    # reported
    assert text.count("*Machine ") == len(present) + len(by_hand)
    assert "## The display's floor on the real module" in text
    assert "## Identification on pads built off their datasheet" in text
    assert "## Unseen materials on pads built off their datasheet" in text
    assert "## Unseen materials on pads built off their datasheet, an aluminium" in text
    assert "## First touches on pads built off their datasheet" in text
    assert "calibrated    0.5 s 100.0 %" in text            # the as-built bench's own text
    for image in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text):
        assert (tmp_path / image).is_file(), image
    assert "Not run" not in text
    assert "could not be written" not in text            # every section read its JSON


def test_a_missing_bench_is_named_not_invented(tmp_path):
    partial = tmp_path / "results"
    partial.mkdir()
    shutil.copy(RESULTS / "transport.json", partial)
    text = write_report(partial, tmp_path / "out" / "report.md").read_text()
    assert "## Transport" in text and "## Physics" not in text
    assert "Not run: physics, identify, render, faults, devices, record" in text
