"""Numbers the command line refuses when it is parsed: every ``--seed``
takes a whole number >= 0 (numpy's generators take no negative seed: a -1
had reached them as a traceback), and contact times, loop rates, timeouts
and ports are bounded."""

import argparse

import pytest

from telethermal.cli import build_parser


def _seed_actions(parser, path=()):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _seed_actions(sub, path + (name,))
        elif "--seed" in action.option_strings:
            yield path, action


SEEDS = list(_seed_actions(build_parser()))


def test_the_commands_with_a_seed_are_found():
    assert len(SEEDS) >= 9, [p for p, _ in SEEDS]


@pytest.mark.parametrize("path, action", SEEDS, ids=[" ".join(p) for p, _ in SEEDS])
def test_a_seed_is_a_whole_number_not_below_zero(path, action):
    assert action.type("0") == 0 and action.type("7") == 7
    for bad in ("-1", "1.5", "x", ""):
        with pytest.raises(argparse.ArgumentTypeError, match="seed|whole number"):
            action.type(bad)


@pytest.mark.parametrize("argv, message", [
    (["session", "--contact-s", "1e6"], "'1e6' is over 600 (a touch of up to 10 minutes"),
    (["session", "--rate-hz", "1e9"], "'1e9' is over 10000"),
    (["demo", "--contact-s", "700"], "'700' is over 600"),
    (["demo", "--rate-hz", "1e9"], "'1e9' is over 10000"),
    (["demo", "--rate-hz", "5"], "'5' is under 20 (two commands inside the Peltier driver's "
                                 "100 ms watchdog)"),
    (["session", "--rate-hz", "10"], "'10' is under 20 (two commands inside the Peltier "
                                     "driver's 100 ms watchdog)"),
    (["simulate", "--seconds", "1e9"], "'1e9' is over 600"),
    (["admin", "send", "slave", "status", "--timeout-s", "-1"], "must be positive and finite"),
    (["admin", "send", "slave", "status", "--timeout-s", "nan"], "must be positive and finite"),
    (["admin", "touch", "--contact-s", "61"], "'61' is over 60 (the master's touch request"),
    (["view", "--port", "99999"], "a port is 1-65535 (0: a free one)"),
    (["view", "--port", "-1"], "a port is 1-65535")])
def test_sizes_and_ports_out_of_range_are_refused_when_parsed(argv, message, capsys):
    """A contact or rate that would fill memory (a 1e6 s session had been
    killed by the kernel, a 1e9 Hz one asked numpy for 452 GiB), a timeout
    that waits forever, a port no socket takes: refused before anything
    runs, saying the bound and why."""
    with pytest.raises(SystemExit) as stop:
        build_parser().parse_args(argv)
    assert stop.value.code == 2
    assert message in " ".join(capsys.readouterr().err.split())


@pytest.mark.parametrize("argv", [
    ["simulate", "--object-temp-c", "-300"], ["simulate", "--pad-temp-c", "-273.15"],
    ["dataset", "import", "x.csv", "--into", "d", "--room-c", "-400"],
    ["admin", "touch", "--object-c", "-274"]])
def test_a_temperature_below_absolute_zero_is_refused(argv, capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(argv)
    assert "below absolute zero (-273.15 C)" in capsys.readouterr().err


def test_a_calibration_window_of_nothing_is_refused_when_parsed(capsys):
    # calibrate pad --window-s 0 had run the fit and blamed the pad's model.
    for value, message in (("0", "must be positive"), ("-0.5", "must be positive"),
                           ("1e4", "is over 60")):
        with pytest.raises(SystemExit):
            build_parser().parse_args(["calibrate", "pad", "--scene", "s", "--data", "d",
                                       "--out", "o", "--window-s", value])
        assert message in capsys.readouterr().err
    with pytest.raises(SystemExit):
        build_parser().parse_args(["calibrate", "pad", "--scene", "s", "--data", "d",
                                   "--out", "o", "--design-sd", "-1"])
    assert "must be >= 0" in capsys.readouterr().err
