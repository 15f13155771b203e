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
    (tmp_path / "physics.json").write_text("{}")
    assert main(["bench", "report", "--results", str(tmp_path), "--out", str(folder)]) == 2
    captured = capsys.readouterr()
    err = " ".join((captured.out + captured.err).split())
    assert f"error: {folder}: a folder, not a file's path" in err, err


def test_a_report_of_no_results_is_refused_not_written(tmp_path, capsys):
    """bench report on a folder that is not there, or holds no bench's JSON
    (a typo in --results), had written a page of "Not run" and exited 0."""
    out = tmp_path / "report.md"
    for results, message in ((tmp_path / "nowhere", "no such folder"),
                             (tmp_path, "no bench's JSON in it")):
        assert main(["bench", "report", "--results", str(results), "--out", str(out)]) == 2
        captured = capsys.readouterr()
        assert message in " ".join((captured.out + captured.err).split())
    assert not out.exists()


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
    assert png(str(tmp_path / "fig.eps")).suffix == ".eps"      # what matplotlib writes
    with pytest.raises(UsageError, match=r"--png .*fig\.xyz: no figure format ends so; "
                                         r"matplotlib writes .*\.png"):
        png(str(tmp_path / "fig.xyz"))
    (tmp_path / "q.png").mkdir()
    with pytest.raises(UsageError, match=r"the figure beside --json, .*q\.png: a folder"):
        png(None, json="q.json")
    with pytest.raises(UsageError, match="a folder; give the figure's file"):
        png(str(tmp_path))
    fig = plt.figure()
    write_figure(fig, tmp_path / "deep" / "er" / "fig.png")    # its folder made
    plt.close(fig)
    assert (tmp_path / "deep" / "er" / "fig.png").stat().st_size > 0


def test_a_bench_refuses_its_json_path_and_methods_before_any_work(tmp_path, capsys):
    """--json a folder (bench physics had run to its end first) and an
    unknown or empty --methods (bench identify had trained for seconds, then
    shown a traceback): refused at once, naming the value."""
    for argv, message in (
            (["bench", "physics", "--json", str(tmp_path)], "a folder; give the report's file"),
            (["bench", "identify", "--json", str(tmp_path / "i.json"), "--methods", "nosuch"],
             "'nosuch' not a method; methods: effusivity-fit"),
            (["bench", "identify", "--json", str(tmp_path / "i.json"), "--methods", ","],
             "not a method")):
        assert main(argv) == 2
        captured = capsys.readouterr()
        assert message in " ".join((captured.out + captured.err).split()), argv
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_folder_given_where_a_file_is_read_is_called_a_folder(tmp_path):
    """It had been reported as missing ("no such config file", "does not
    exist"), which sends a user looking for a typo."""
    from telethermal.errors import DatasetError, SceneError, TelethermalError
    from telethermal.physics.scene import load_scene
    from telethermal.record.importer import import_recordings
    from telethermal.tomltables import read_toml

    with pytest.raises(TelethermalError, match="a folder, not a config file"):
        read_toml(tmp_path, "config file")
    with pytest.raises(SceneError, match="a folder, not a scene file"):
        load_scene(str(tmp_path))
    with pytest.raises(DatasetError, match="a folder, not a recording or CSV file"):
        import_recordings([tmp_path], tmp_path / "ds")
