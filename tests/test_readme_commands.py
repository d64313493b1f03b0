"""Every `antarium ...` command the README shows parses as written, and its sub-command answers --help."""

import re
import shlex
import subprocess
from pathlib import Path

import pytest

from antarium.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def readme_commands() -> list[str]:
    """Command lines from the README's indented blocks and `inline code`; `a | b | c` alternatives expanded."""
    text = README.read_text()
    found = [line.strip().split("  #")[0].strip() for line in text.splitlines() if line.startswith("    antarium ")]
    for span in re.findall(r"`(antarium [^`]+)`", text):
        if span.startswith("antarium.") or "(" in span:
            continue
        first, *alternatives = [part.strip() for part in span.split(" | ")]
        found.append(first)
        found += [first.rsplit(" ", 1)[0] + " " + alt for alt in alternatives]
    return sorted(set(found))


def test_the_readme_shows_the_commands_we_check():
    commands = readme_commands()
    assert "antarium ant demo" in commands and "antarium bench jitter" in commands
    assert len(commands) >= 10


@pytest.mark.parametrize("line", readme_commands())
def test_a_readme_command_parses_as_written(line):
    argv = shlex.split(line)[1:]
    args = build_parser().parse_args(argv)  # argparse exits (SystemExit 2) on a missing or unknown argument
    assert args.command == argv[0]


@pytest.mark.parametrize("line", readme_commands())
def test_a_readme_command_answers_help(line, capsys):
    words = [w for w in shlex.split(line)[1:] if not w.startswith("-")][:2]
    with pytest.raises(SystemExit) as stop:
        build_parser().parse_args(words[:1] + (words[1:] if words[0] in ("ant", "bench") else []) + ["--help"])
    assert stop.value.code == 0
    assert "usage: antarium" in capsys.readouterr().out


def test_the_readme_and_make_demo_say_how_to_reach_the_installed_commands(tmp_path):
    """`make demo` installs into a virtual environment: `antarium ...` is not on a new user's PATH until it is
    activated, which both the README and the end of `make demo` say."""
    assert "`. .venv/bin/activate`" in README.read_text()
    venv = tmp_path / "venv"  # -n: nothing is installed or run, the recipe is printed
    recipe = subprocess.run(["make", "-n", "-s", "demo", f"VENV={venv}"], cwd=ROOT, check=True, capture_output=True,
                            text=True).stdout
    assert f"{venv}/bin/antarium demo --out demo-output" in recipe and f". {venv}/bin/activate" in recipe
