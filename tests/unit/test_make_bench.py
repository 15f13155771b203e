"""The Makefile's bench targets (read with ``make -n``, nothing run): each
runs every bench the report has a section for, into one folder, and writes
its report from that folder; only bench-full writes the committed files."""

import shutil
import subprocess
from pathlib import Path

import pytest

from telethermal.bench.report import SECTIONS

ROOT = Path(__file__).parents[2]

pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="no make")


def _commands(target: str) -> list[list[str]]:
    out = subprocess.run(["make", "-n", "-C", str(ROOT), target, "OUT=outdir"],
                         capture_output=True, text=True, check=True).stdout
    return [line.split()[1:] for line in out.splitlines()
            if line.split()[:1] and line.split()[0].endswith("/telethermal")]


@pytest.mark.parametrize("target, folder, report", [
    ("bench-full", "bench/results", "bench/report.md"),
    ("bench", "outdir/bench", "outdir/bench/report.md"),
    ("bench-quick", "outdir/bench-quick", "outdir/bench-quick/report.md")])
def test_every_bench_into_one_folder_then_its_report(target, folder, report):
    commands = _commands(target)
    benches = [c for c in commands if c[0] == "bench" and c[1] != "report"]
    assert [c[1] for c in benches] == [name for name, _ in SECTIONS]
    for c in benches:
        assert c[:4] == ["bench", c[1], "--json", f"{folder}/{c[1]}.json"]
        assert "--png" not in c                     # the figure beside its JSON
    assert commands[-1] == ["bench", "report", "--results", folder, "--out", report]


@pytest.mark.parametrize("target, folder", [("bench", "outdir/bench"),
                                             ("bench-quick", "outdir/bench-quick")])
def test_the_reduced_runs_train_once_and_give_the_session_benches_the_files(target, folder,
                                                                           monkeypatch):
    """First `telethermal models` on the benches' scene and seed, then
    --models on every bench that takes it (those that run sessions), each
    command one the CLI parses (the folder, which make would write first,
    not checked here)."""
    from telethermal.bench import models as bench_models
    from telethermal.bench.models import TRAINING_SEED
    from telethermal.cli import build_parser

    monkeypatch.setattr(bench_models, "checked_folder", lambda *a: {})

    commands = _commands(target)
    models = f"{folder}/models"
    assert commands[0] == ["models", "--scene", "fingertip-7", "--seed", str(TRAINING_SEED),
                           "--out", models]
    parser = build_parser()
    given = set()
    for c in commands[1:-1]:
        args = parser.parse_args(c)
        if getattr(args, "models", None) is not None:
            assert args.models == models
            given.add(c[1])
    assert given == {name for name, _ in SECTIONS
                     if "--models" in _help(parser, name)}
    assert given == {"render", "faults", "devices", "record", "view"}


def _help(parser, bench: str) -> str:
    import contextlib
    import io
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit):
        parser.parse_args(["bench", bench, "--help"])
    return out.getvalue()


def test_bench_full_runs_the_defaults_and_the_others_reduce():
    full = _commands("bench-full")
    assert all(len(c) == 4 for c in full[:-1])      # bench NAME --json PATH, no option
    for target in ("bench", "bench-quick"):
        assert any(len(c) > 4 for c in _commands(target)[:-1]), target
