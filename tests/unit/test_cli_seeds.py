"""Every ``--seed`` of the command line takes a whole number >= 0 and
refuses anything else when the line is parsed (numpy's generators take no
negative seed: a -1 had reached them as a traceback)."""

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
