"""``telethermal bench report``: every benchmark's JSON in one Markdown
report with its figures (speed against error), each stating the machine,
the date and the command that produced it. Each section is the one the
bench itself prints (:mod:`telethermal.bench.markdown`: one renderer)."""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

from telethermal.bench import (faults_text, identify_text, render_text,  # noqa: E402
                               sections, unseen_text)
from telethermal.bench.markdown import Page, provenance, terminal  # noqa: E402
from telethermal.bench.options import off_defaults  # noqa: E402
from telethermal.jsonfile import write_text  # noqa: E402


log = logging.getLogger("telethermal.bench")


def _load(results: Path, name: str) -> dict | None:
    path = results / f"{name}.json"
    return json.loads(path.read_text()) if path.is_file() else None


SECTIONS = (("physics", sections.physics), ("identify", identify_text.section),
            ("render", render_text.section), ("transport", sections.transport),
            ("faults", faults_text.section), ("devices", sections.devices),
            ("record", sections.record), ("view", sections.view),
            ("unseen", unseen_text.section))
#: Reported when its JSON is there, not run by the Makefile's bench targets:
#: ``telethermal bench skin-floor`` takes 20 minutes at its defaults (10
#: with --quick), past bench-quick's 3 and most of bench's 15; the as-built
#: benches (``bench identify|unseen|render --as-built 0.15``) calibrate five
#: pads, 10-40 minutes each run.
BY_HAND = (("skin-floor", sections.skin_floor),
           ("identify-as-built", sections.as_built(
               "Identification on pads built off their datasheet", "identify_as_built")),
           ("unseen-as-built", sections.as_built(
               "Unseen materials on pads built off their datasheet", "unseen_as_built")),
           # The same with a metal as high as brass among the references
           # (--references aluminium,steel,wood): does it pin the outer layers?
           ("unseen-as-built-aluminium", sections.as_built(
               "Unseen materials on pads built off their datasheet, an aluminium reference",
               "unseen_as_built")),
           ("render-as-built", sections.as_built(
               "First touches on pads built off their datasheet", "render_as_built")))


def write_report(results: str | Path, out_md: str | Path, command: str = "") -> Path:
    results, out_md = Path(results), Path(out_md)
    from telethermal.errors import BenchError
    if not results.is_dir():
        raise BenchError(f"--results {results}: no such folder (the benches' JSON files: "
                         "bench/results, or make bench's out/bench)")
    if not any((results / f"{name}.json").is_file() for name, _ in SECTIONS + BY_HAND):
        raise BenchError(f"--results {results}: no bench's JSON in it (physics.json, "
                         "render.json, ...): run the benches into it first")
    out = out_md.parent
    out.mkdir(parents=True, exist_ok=True)
    where = Path(os.path.relpath(results.resolve(), out.resolve())).as_posix()
    where = "beside this file" if where == "." else f"in `{where}/`"
    lines = ["# telethermal: speed against error", "",
             "Every figure below comes from a `telethermal bench ...` command run on the "
             "machine and at the date stated under it; the JSON it was read from and the "
             f"bench's own figures are {where}. Report written by "
             f"`{command or 'telethermal bench report'}`.", ""]
    page = Page(out=out, results=results)
    missing, reduced, body = [], [], []
    for name, section in SECTIONS + BY_HAND:
        d = _load(results, name)
        if d is None:
            if (name, section) in SECTIONS:
                missing.append(name)
            continue
        cut, _ = off_defaults(d.get("command", ""))
        if cut:
            reduced.append(f"{name} `{' '.join(cut)}`")
        body += _guarded(name, section, d, page)
    if reduced:
        lines += ["Reduced runs (options other than the bench's defaults: fewer methods, "
                  "seeds, trials, rounds or settings; their figures are not the committed "
                  "ones): " + "; ".join(reduced) + ".", ""]
    lines += body
    if missing:
        lines += [f"Not run: {', '.join(missing)} (no JSON in {results})."]
    return write_text(out_md, "\n".join(lines) + "\n")


def _guarded(name: str, section, d: dict, page: Page) -> list[str]:
    """``section(d, page)``, or, for a JSON it cannot read (written by an
    older bench: a field it lacks), a section that says so: the rest of the
    report is still written."""
    try:
        return section(d, page)
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        log.warning("bench report: the %s section was not written from %s.json: %s: %s",
                    name, name, type(exc).__name__, exc)
        return [f"## {name}", "", f"The section could not be written from `{name}.json` "
                f"({type(exc).__name__}: {exc}): a JSON from an older bench; re-run "
                f"`telethermal bench {name}`.", "", provenance(d), ""]


def bench_text(name: str, report: dict, json_path: str | Path, *written,
               width: int | None = None) -> str:
    """What ``telethermal bench NAME`` prints: its section of the report
    (the same lines, from the same JSON; its figures left out, a terminal
    shows no image), then the files it wrote (``width``: the terminal's,
    120 columns in a pipe)."""
    section = dict(SECTIONS + BY_HAND)[name]
    folder = Path(json_path).parent
    page = Page(out=folder, results=folder, draw=False)
    text = terminal([line for line in section(report, page) if not line.startswith("![")],
                    width)
    return text + "\nwrote " + " and ".join(str(p) for p in (json_path, *written))
