"""The command line explains itself: every option of every subcommand has a
help text, ``telethermal --help`` says what the tool is, ``identify methods``
prints each method's whole description and marks the default, ``dataset
validate`` refuses a column the identifiers would not find, and errors name
options, not Python arguments."""

from __future__ import annotations

import argparse
import shutil

import pytest

from telethermal.cli import build_parser, main
from telethermal.data.dataset import load_dataset, staged_dir
from telethermal.errors import DatasetError


def options_without_help(parser: argparse.ArgumentParser, path=("telethermal",)):
    """(command, option) of every argument, in every subcommand, without help."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helped = {a.dest for a in action._choices_actions if a.help}
            for name, sub in action.choices.items():
                if name not in helped:
                    yield " ".join(path), name
                yield from options_without_help(sub, (*path, name))
        elif isinstance(action, (argparse._HelpAction, argparse._VersionAction)):
            continue
        elif not action.help or action.help == argparse.SUPPRESS:
            yield " ".join(path), "/".join(action.option_strings) or action.dest


def test_every_option_of_every_command_has_help():
    missing = [f"{cmd} {opt}" for cmd, opt in options_without_help(build_parser())]
    assert missing == [], "options without help=:\n" + "\n".join(missing)


def test_the_walk_finds_an_option_without_help():
    parser = argparse.ArgumentParser(prog="t")
    sub = parser.add_subparsers()
    p = sub.add_parser("a", help="a command")
    p.add_argument("--x", help="has one")
    p.add_argument("--y")
    sub.add_parser("b")
    assert list(options_without_help(parser, ("t",))) == [("t a", "--y"), ("t", "b")]


def test_top_level_help_says_what_the_tool_is(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    assert "thermal telepresence" in out and "telethermal demo" in out
    assert "The ``telethermal`` command" not in out


def test_identify_methods_shows_whole_descriptions_and_the_default(capsys):
    from telethermal.ident.registry import METHODS
    from telethermal.teleop.models import DEFAULT_METHOD

    assert main(["identify", "methods"]) == 0
    out = capsys.readouterr().out
    blocks = {b.split("\n", 1)[0]: " ".join(b.split("\n", 1)[1].split())
              for b in out.strip().split("\n\n")}
    assert set(blocks) == set(METHODS)
    assert blocks[DEFAULT_METHOD].startswith("[default]")
    assert sum("[default]" in text for text in blocks.values()) == 1
    for name, text in blocks.items():
        assert text.endswith((".", ")")), f"{name}: cut short: {text[-60:]!r}"
        assert "``" not in text and ":class:" not in text, name


def test_dataset_validate_refuses_a_misspelled_flux_column(tmp_path, capsys):
    assert main(["simulate", "--pad", "alumina", "--object", "wood", "--pad-temp-c", "34",
                 "--object-temp-c", "24", "--seconds", "0.5", "--rate-hz", "100",
                 "--out", str(tmp_path / "ok")]) == 0
    assert main(["dataset", "validate", str(tmp_path / "ok")]) == 0
    bad = tmp_path / "bad"
    shutil.copytree(tmp_path / "ok", bad)
    trial = bad / load_dataset(bad)[0].file
    trial.write_text(trial.read_text().replace("heat_flux_W_m2", "heatflux_W_m2", 1))
    capsys.readouterr()
    assert main(["dataset", "validate", str(bad)]) == 2
    captured = capsys.readouterr()
    err = " ".join((captured.out + captured.err).split())
    assert "heatflux_W_m2" in err and "did you mean 'heat_flux_W_m2'" in err
    assert trial.name in err


def test_a_dataset_without_heat_flux_is_refused_with_its_columns(tmp_path):
    from telethermal.data.dataset import check_identifier_channels

    assert main(["simulate", "--pad", "alumina", "--object", "wood", "--pad-temp-c", "34",
                 "--object-temp-c", "24", "--seconds", "0.5", "--rate-hz", "100",
                 "--out", str(tmp_path / "ok")]) == 0
    trials = load_dataset(tmp_path / "ok")
    trials[0].channels = {k: v for k, v in trials[0].channels.items() if k != "heat_flux_W_m2"}
    with pytest.raises(DatasetError, match="no 'heat_flux_W_m2' column"):
        check_identifier_channels(trials, tmp_path / "ok")


def test_a_full_output_folder_error_names_the_option_not_a_python_argument(tmp_path):
    (tmp_path / "x").write_text("")
    with pytest.raises(DatasetError) as err:
        with staged_dir(tmp_path):
            pass
    assert "--force" in str(err.value) and "overwrite" not in str(err.value)
