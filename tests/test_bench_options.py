"""`antarium bench TARGET` takes only the options its target uses (one table, `antarium.bench.OPTIONS`), refuses
the others in one line naming the target and what it takes, and says in --help what an option means per target."""

from __future__ import annotations

import argparse

import pytest

from antarium.bench import OPTIONS, TARGETS
from antarium.cli import main
from antarium.commands.bench import USUAL, add_arguments


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    return parser


def test_every_target_and_option_is_in_the_table():
    assert set(OPTIONS) == set(TARGETS)
    options = {s for a in _parser()._actions for s in a.option_strings} - {"-h", "--help", "--json"}
    assert options == set(USUAL) and set().union(*map(set, OPTIONS.values())) == options


@pytest.mark.parametrize("target, args, refused", [
    ("render", ["--seconds", "3"], "--seconds"),
    ("monitor", ["--path", "cpu", "--machine-probe", "--sky-every", "5"], "--machine-probe, --path, --sky-every"),
    ("jitter", ["--path", "gpu"], "--path"),
    ("loop", ["--work-ms", "1"], "--work-ms"),
    ("protocol", ["--browser-idle"], "--browser-idle"),
])
def test_an_option_the_target_does_not_take_is_refused_in_one_line(target, args, refused, capsys):
    assert main(["bench", target, *args]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert captured.out == "" and "\n" not in err
    assert f"bench {target} takes only {', '.join([*OPTIONS[target], '--json'])}; not {refused}" in err


def test_help_says_what_a_reinterpreted_option_means_per_target():
    helps = {a.option_strings[0]: a.help for a in _parser()._actions if a.option_strings}
    assert "experiment: NOT seconds: the route length in metres" in helps["--seconds"]
    assert "experiment: NOT frames: the number of runs" in helps["--frames"]
    assert "trackball: N FicTrac lines parsed" in helps["--frames"]
    assert "render" not in helps["--seconds"]  # render does not take it
    assert "(only loop, render)" in helps["--path"]
