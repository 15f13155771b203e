"""The writers of reports and figures (``telethermal.jsonfile``): all of a
file or nothing, a folder given for a file refused by name, and the command
line saying so in one line instead of a traceback."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from telethermal.cli import main  # noqa: E402
from telethermal.jsonfile import write_figure, write_json, write_text  # noqa: E402


def test_a_folder_given_for_a_file_is_refused_and_nothing_is_written(tmp_path):
    folder = tmp_path / "out"
    folder.mkdir()
    with pytest.raises(IsADirectoryError, match="a folder, not a file's path"):
        write_json(folder, {"a": 1})
    fig = plt.figure()
    with pytest.raises(IsADirectoryError, match="a folder, not an image file's path"):
        write_figure(fig, folder)
    plt.close(fig)
    assert list(folder.iterdir()) == [] and sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_figure_that_fails_to_save_keeps_the_old_file_and_leaves_no_part(tmp_path):
    old = write_text(tmp_path / "plot.xyz", "the old figure")
    fig = plt.figure()
    with pytest.raises(ValueError, match="xyz"):                   # no such format
        write_figure(fig, old)
    plt.close(fig)
    assert old.read_text() == "the old figure"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plot.xyz"]


def test_the_command_line_names_the_path_instead_of_a_traceback(tmp_path, capsys):
    folder = tmp_path / "report.md"
    folder.mkdir()
    assert main(["bench", "report", "--results", str(tmp_path), "--out", str(folder)]) == 2
    captured = capsys.readouterr()
    err = " ".join((captured.out + captured.err).split())
    assert f"error: {folder}: a folder, not a file's path" in err, err


def test_a_figure_path_is_checked_before_any_work(tmp_path):
    """--png: a folder, or a suffix no figure is written as, refused by name
    before the command runs (identify eval had written its JSON, then
    failed on the figure with a traceback); the default beside the JSON."""
    import argparse

    from telethermal.cli._common import _png
    from telethermal.errors import UsageError

    def png(value, json="r.json"):
        return _png(argparse.Namespace(png=value, json=str(tmp_path / json)))

    assert png(None) == tmp_path / "r.png"
    assert png(str(tmp_path / "new" / "fig.svg")) == tmp_path / "new" / "fig.svg"
    with pytest.raises(UsageError, match=r"a figure is written as \.png, \.pdf, \.svg"):
        png(str(tmp_path / "fig.xyz"))
    with pytest.raises(UsageError, match="a folder; give the figure's file"):
        png(str(tmp_path))
    fig = plt.figure()
    write_figure(fig, tmp_path / "deep" / "er" / "fig.png")    # its folder made
    plt.close(fig)
    assert (tmp_path / "deep" / "er" / "fig.png").stat().st_size > 0
