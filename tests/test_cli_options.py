"""Command-line hygiene: every option explains itself, calibrate --dry-run needs no rig file, the packaging is
quiet (issue #20, point 13)."""

import argparse
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from antarium.cli import build_parser, has_default, main

ROOT = Path(__file__).resolve().parents[1]


def _parsers(parser: argparse.ArgumentParser, name: str = "antarium"):
    """(name, parser) for `parser` and every sub-command below it."""
    yield name, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub in action.choices.items():
                yield from _parsers(sub, f"{name} {sub_name}")


def test_every_ant_option_has_help():
    ant = dict(_parsers(build_parser()))["antarium ant"]
    missing = [f"{name} {'/'.join(a.option_strings) or a.dest}" for name, p in _parsers(ant, "antarium ant")
               for a in p._actions
               if not isinstance(a, argparse._HelpAction | argparse._SubParsersAction) and not a.help]
    assert missing == []


def test_every_option_with_a_default_shows_it_in_its_help():
    """`antarium trackball --port`, `ant run --length`, `ant displace --lateral-cm` (50), ... said nothing of their
    defaults: every option whose default is a value says it (`cli._finish` adds what a help leaves out)."""
    silent = [f"{name} {a.option_strings[0]}" for name, p in _parsers(build_parser()) for a in p._actions
              if a.option_strings and has_default(a) and "default" not in p._get_formatter()._expand_help(a).lower()]
    assert silent == []
    parsers = dict(_parsers(build_parser()))
    assert "(default 50.0)" in " ".join(parsers["antarium ant displace"].format_help().split())
    assert "(default 0.0)" in " ".join(parsers["antarium ant run"].format_help().split())  # a zero is shown too


#: every option that takes a duration in seconds, with what else its command needs to get that far
DURATIONS = [("serve", "--seconds"), ("emulate", "--seconds"), ("bench", "loop", "--seconds"),
             ("servosphere", "--simulate", "--seconds"), ("trackball", "--emulate", "--seconds"),
             ("trackball", "--emulate", "--unplug-at"), ("trackball", "--emulate", "--replug-after"),
             ("check", "--timeout-s")]


@pytest.mark.parametrize("value", ["-1", "0", "nan"])
@pytest.mark.parametrize("command", DURATIONS, ids=" ".join)
def test_a_duration_that_is_not_positive_is_refused_in_one_line(command, value, capsys):
    assert main([*command, value]) == 2
    err = capsys.readouterr().err.strip()
    shown = "nan" if value == "nan" else f"{float(value):g}"
    assert err == f"antarium {command[0]}: error: {command[-1]} must be a positive number of seconds, got {shown}"


def test_calibrate_dry_run_needs_no_config(capsys):
    assert main(["trackball", "calibrate", "--emulate", "--dry-run", "--turns", "0.25"]) == 0
    assert "dry run: rig config not changed" in capsys.readouterr().out


def test_calibrate_without_config_or_dry_run_says_what_is_needed(capsys):
    assert main(["trackball", "calibrate", "--emulate"]) == 2
    assert "needs --config RIG.toml" in capsys.readouterr().err


def test_building_the_package_is_quiet_about_the_shipped_layout(tmp_path):
    src = tmp_path / "src"
    files = subprocess.run(["git", "ls-files"], cwd=ROOT, check=True, capture_output=True, text=True).stdout.split()
    for name in files:
        if (ROOT / name).is_file():
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, src / name)
    shutil.copy2(ROOT / "pyproject.toml", src / "pyproject.toml")
    out = subprocess.run([sys.executable, "-c", "from setuptools import setup; setup()", "-q", "build_py", "-d",
                          str(tmp_path / "built")], cwd=src, check=True, capture_output=True, text=True)
    assert "is absent from the `packages` configuration" not in out.stdout + out.stderr
    assert (tmp_path / "built" / "antarium" / "geometry" / "data" / "layout.npz").is_file()


def test_every_command_and_action_says_what_it_does_in_its_own_help():
    undescribed = [name for name, p in _parsers(build_parser()) if name != "antarium" and not p.description]
    assert undescribed == []
    assert "walk the ant along a route while its model learns" in dict(_parsers(build_parser()))[
        "antarium ant learn"].format_help()


def test_debug_is_taken_after_an_ant_action_too(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    argv = ["ant", "demo", "--out", str(blocker / "out")]
    assert main(argv) == 2 and "a part of the path is a file" in capsys.readouterr().err
    with pytest.raises(NotADirectoryError):  # --debug after ACTION, as its help says: the traceback instead
        main([*argv, "--debug"])


@pytest.mark.parametrize("argv", [[], ["ant"]], ids=["antarium", "antarium ant"])
def test_a_missing_command_lists_the_commands_with_their_purposes(argv, capsys):
    with pytest.raises(SystemExit) as stop:
        main(argv)
    err = capsys.readouterr().err
    assert stop.value.code == 2 and "the following arguments are required" in err.splitlines()[-1]
    listed = dict(_parsers(build_parser()))[" ".join(["antarium", *argv])].format_help()
    assert listed in err  # every command's name and one-line purpose, as --help shows them


def test_ctrl_c_in_a_command_is_one_line(monkeypatch, capsys):
    """A command stopped by Ctrl-C ended with exit status 130 and not a word."""
    from antarium.commands import layout

    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(layout, "run", interrupted)
    assert main(["layout"]) == 130
    assert capsys.readouterr().err.strip() == "antarium layout: interrupted (Ctrl-C)"
