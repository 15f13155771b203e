"""bench report: each bench's figure is linked where the bench wrote it (one
copy of each figure), and a reduced run says so."""

import json
import re
import shutil
from pathlib import Path

from telethermal.bench.options import off_defaults, reduced_options
from telethermal.bench.report import write_report

RESULTS = Path(__file__).parents[2] / "bench" / "results"


def _images(text: str) -> list[str]:
    return re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)


def test_figures_are_linked_where_the_benches_wrote_them_not_copied(tmp_path):
    out = tmp_path / "elsewhere" / "report.md"
    text = write_report(RESULTS, out).read_text()
    images = _images(text)
    for name in ("physics.png", "render.png", "faults.png", "faults-traces.png",
                 "identify.png"):
        linked = [i for i in images if i.endswith("/" + name)]
        assert len(linked) == 1, (name, images)
        assert (out.parent / linked[0]).resolve() == (RESULTS / name).resolve()
    # The only figure beside the report is the one the report draws itself
    # (the transport bench writes none); no bench figure is copied.
    assert sorted(p.name for p in out.parent.glob("*.png")) == ["transport.png"]


def test_a_report_beside_its_results_links_them_by_name(tmp_path):
    results = tmp_path / "bench"
    shutil.copytree(RESULTS, results)
    text = write_report(results, results / "report.md").read_text()
    assert "![physics](physics.png)" in text
    assert "![faults-traces](faults-traces.png)" in text


def test_a_missing_bench_figure_is_drawn_from_its_json_beside_the_report(tmp_path):
    results = tmp_path / "results"
    results.mkdir()
    d = json.loads((RESULTS / "physics.json").read_text())
    d.pop("png", None)                       # nowhere to find the bench's own figure
    (results / "physics.json").write_text(json.dumps(d))
    text = write_report(results, tmp_path / "report.md").read_text()
    assert _images(text) == ["physics_speed_error.png"]
    assert (tmp_path / "physics_speed_error.png").is_file()


def test_reduced_options_are_those_that_change_what_is_measured():
    assert reduced_options("telethermal bench faults --json a.json --png a.png --jobs 2") == []
    assert reduced_options("telethermal bench faults --json a.json --quick --seeds 2") == [
        "--quick", "--seeds 2"]
    assert reduced_options("telethermal bench identify --methods=pca-fnn --json x") == [
        "--methods=pca-fnn"]
    assert reduced_options("telethermal bench identify --json OUT --png PNG (copied by "
                           "hand)") == []
    assert reduced_options("unbalanced 'quote --quick") == ["--quick"]
    # The as-built benches at the sd and pad count are the benches
    # themselves; fewer pads or another sd are a reduction.
    assert reduced_options("telethermal bench identify --as-built 0.15 --json x") == []
    assert reduced_options("telethermal bench unseen --as-built=0.15 --pads 5 --json x") == []
    assert reduced_options("telethermal bench identify --as-built 0.3 --pads 2 --json x") == [
        "--as-built 0.3", "--pads 2"]
    # Other reference blocks are another setting to compare, not a reduction.
    assert off_defaults("telethermal bench unseen --as-built 0.15 --references "
                        "aluminium,steel,wood --seeds 2 --json x") == (
        ["--seeds 2"], ["--references aluminium,steel,wood"])
    assert off_defaults("telethermal bench identify --as-built 0.15 --references "
                        "wood,steel,plexiglass --json x") == ([], [])      # the default set


def test_a_reduced_run_is_named_in_the_report(tmp_path):
    results = tmp_path / "results"
    results.mkdir()
    d = json.loads((RESULTS / "record.json").read_text())
    d["command"] = "telethermal bench record --json x/record.json --rounds 1"
    (results / "record.json").write_text(json.dumps(d))
    text = write_report(results, tmp_path / "report.md").read_text()
    assert "Reduced runs" in text and "record `--rounds 1`" in text
    assert text.count("**Reduced run**") == 1
    full = write_report(RESULTS, tmp_path / "full.md").read_text()
    assert "Reduced run" not in full
    # The committed comparison with other reference blocks says it is one.
    assert "**Another setting** (`--references aluminium,steel,wood`)" in full


def test_a_reduced_view_run_is_named_from_its_command(tmp_path):
    results = tmp_path / "results"
    results.mkdir()
    d = json.loads((RESULTS / "view.json").read_text())
    d.update(touches_per_mode=1, contact_s=1.0,
             command="telethermal bench view --json x/view.json --touches 1 --contact-s 1")
    (results / "view.json").write_text(json.dumps(d))
    text = write_report(results, results / "report.md").read_text()
    assert "view `--touches 1 --contact-s 1`" in text
    assert "are beside this file" in text
