"""The user guides docs/servosphere.md, docs/fictrac.md and docs/monitor.md stay true: the commands and options
they name exist, their config snippets are accepted as written, the status keys and printed lines they quote are
the code's."""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from antarium import bus
from antarium.cli import build_parser, main
from antarium.config import MonitorSection
from antarium.core.clock import SimulatedClock
from antarium.locomotion import open_source

DOCS = Path(__file__).resolve().parents[1] / "docs"
GUIDES = ("servosphere.md", "fictrac.md", "monitor.md")


def _subcommands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def _command_lines(text: str) -> list[str]:
    """Every `antarium ...` command of a guide: code lines (fenced or indented) and inline `...` spans."""
    lines = [m.group(1) for m in re.finditer(r"^\s*(antarium \S.*)$", text, re.MULTILINE)]
    lines += [m.group(1) for m in re.finditer(r"`(antarium [^`]+)`", text)]
    return [line.split("#")[0].strip() for line in lines]


@pytest.mark.parametrize("guide", GUIDES)
def test_every_option_a_guide_gives_a_command_exists(guide):
    subcommands = _subcommands()
    commands = _command_lines((DOCS / guide).read_text())
    assert commands, f"{guide} names no antarium command"
    for command in commands:
        words = command.split()
        if words[1] not in subcommands:  # prose such as "antarium serve: the monitor stopped ..."
            assert words[1].rstrip(":") in subcommands, command
            continue
        known = {s for a in subcommands[words[1]]._actions for s in a.option_strings}
        unknown = [w.split("=")[0] for w in words[2:] if w.startswith("--") and w.split("=")[0] not in known]
        assert not unknown, f"{guide}: `{command}` gives {unknown}, which `antarium {words[1]}` does not take"


def _servosphere_config(uncomment: bool) -> dict:
    """docs/servosphere.md's rig config, with its commented `key = value` lines taken in when `uncomment`
    (all but `calibration`, which only a real rig takes: the guide says so)."""
    block = re.search(r"```toml\n(.*?)```", (DOCS / "servosphere.md").read_text(), re.DOTALL).group(1)
    if uncomment:
        block = re.sub(r"^# (?!calibration)(\w+ = )", r"\1", block, flags=re.MULTILINE)
    return tomllib.loads(block)


@pytest.mark.parametrize("uncomment", [False, True])
def test_the_servosphere_guides_config_is_accepted_as_written(uncomment):
    """The guide's [locomotion] block, its commented options taken in one by one as a lab would, is valid TOML
    and opens the source (until 2026-11-28 the commented `kp = 1.25, kd = 0.005, ...` was one line: invalid TOML)."""
    config = _servosphere_config(uncomment)
    options = {k: v for k, v in config["locomotion"].items() if k != "source"}
    if uncomment:
        assert {"kp", "kd", "counter_rotate", "threshold", "area_mm2", "rotors", "steppers"} <= set(options)
    src = open_source("servosphere", clock=SimulatedClock(), tether=config["loop"]["tether"],
                      ball_radius=config["loop"]["ball_radius_m"], **options)
    src.stop()


def test_antarium_servosphere_runs_a_config_that_sets_process(tmp_path, capsys):
    """`process = false` (the guide's option for `antarium serve`) in the config: `antarium servosphere --config`
    keeps its loop in a thread anyway and runs, rather than failing with a TypeError traceback."""
    config = tmp_path / "rig.toml"
    config.write_text('[loop]\nball_radius_m = 0.06\n[locomotion]\nsource = "servosphere"\ncamera = "simulated"\n'
                      'link = "simulated"\nprocess = false\n')
    assert main(["servosphere", "--config", str(config), "--seconds", "0.05"]) == 0
    assert "control loop" in capsys.readouterr().out


def test_the_fictrac_guides_counter_names_are_status_keys():
    """Every counter the guide names for columns 1 and 23, or as `status()["..."]`, is a key of the status."""
    text = (DOCS / "fictrac.md").read_text()
    used_as = [row.split("|")[4] for row in re.findall(r"^\| (?:1|23) \|.*$", text, re.MULTILINE)]
    names = {n for cell in used_as for n in re.findall(r"`(\w+)`", cell)}
    names |= set(re.findall(r'status\(\)\["(\w+)"\]', text))
    assert {"gaps", "lost_frames", "malformed", "dropped_samples"} <= names
    status = open_source("fictrac", transport="udp", host="127.0.0.1", port=0).status()
    assert names - set(status) == set(), f"named in docs/fictrac.md but not in status(): {names - set(status)}"


def test_the_monitor_guides_config_block_is_the_sections_defaults():
    block = re.search(r"```toml\n(.*?)```", (DOCS / "monitor.md").read_text(), re.DOTALL).group(1)
    shown = tomllib.loads(block)["monitor"]
    defaults = MonitorSection().model_dump()
    assert shown == {k: defaults[k] for k in shown}


def test_the_monitor_prints_the_line_the_guide_quotes(tmp_path):
    quoted = re.search(r"prints `(antarium monitor: rig [^`]+)`", (DOCS / "monitor.md").read_text()).group(1)
    config = tmp_path / "rig.toml"
    config.write_text(f'[bus]\nlisten = ["{bus.free_tcp_endpoint()}"]\n')
    proc = subprocess.Popen([sys.executable, "-m", "antarium", "monitor", "--config", str(config), "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        line = proc.stdout.readline().strip()
    finally:
        proc.terminate()
        proc.wait(30)
        proc.stdout.close()
    assert re.sub(r":\d+/", ":PORT/", line) == re.sub(r":\d+/", ":PORT/", quoted)


def _resolve(dotted: str):
    """The object a guide names as `antarium.a.b.Name`, or `module.Name` / `module.py` of the servosphere package
    (`trial_log.X`: antarium.trial_log)."""
    from importlib import import_module

    parts = dotted.removesuffix(".py").split(".")
    if parts[0] != "antarium":
        parts = ["antarium"] + (["locomotion", "servosphere"] if parts[0] != "trial_log" else []) + parts
    for split in range(len(parts), 0, -1):
        try:
            obj = import_module(".".join(parts[:split]))
        except ModuleNotFoundError:
            continue
        for name in parts[split:]:
            obj = getattr(obj, name)
        return obj
    raise ModuleNotFoundError(dotted)


@pytest.mark.parametrize("guide", GUIDES)
def test_every_module_and_name_a_guide_points_to_exists(guide):
    text = (DOCS / guide).read_text()
    names = set(re.findall(r"`(antarium\.[\w.]+)`", text))
    if guide == "servosphere.md":
        names |= set(re.findall(r"`((?:kinematics|tracker|controller|protocol|link|firmware|rig|camera|source|process"
                                r"|trial_log)\.\w+(?:\.py)?)`", text))
    assert names
    for name in sorted(names):
        assert _resolve(name) is not None, name


def test_the_servosphere_guides_limits_are_the_codes():
    """The counts and windows the guide gives in words are the constants the code uses."""
    from antarium.locomotion.servosphere import link, source

    text = " ".join((DOCS / "servosphere.md").read_text().split())
    assert source.MAX_BAD_FRAMES == 350 and "350 in a row (0.5 s at 700 frames/s, `source.MAX_BAD_FRAMES`)" in text
    assert link.MAX_STALLED_WRITES == 100 and "100 commands in a row" in text
    assert (source.WALK_WINDOW_S, source.WALK_MIN_S) == (0.08, 0.05)
    assert "over the last 80 ms (none before 50 ms" in text


@pytest.mark.parametrize("max_queue", [0, -1, 1.5, True])
def test_fictrac_max_queue_must_be_a_whole_number_of_samples(max_queue):
    """max_queue = 0 was accepted and dropped every sample; -1 and 1.5 gave Python's messages naming no option."""
    from antarium.locomotion import open_source

    with pytest.raises(ValueError, match=r"^FicTrac max_queue must be an integer >= 1 \(samples that may wait for "
                                         r"read\(\)\), got "):
        open_source("fictrac", port=0, max_queue=max_queue)


def test_a_real_servosphere_without_a_port_is_told_which_key_is_missing():
    from antarium.locomotion import open_source

    with pytest.raises(ValueError, match=r"servosphere link 'serial' needs \[locomotion\] port"):
        open_source("servosphere", camera="opencv", link="serial", camera_index="/nonexistent.avi",
                    calibration={"mm_per_px": 0.1, "centre_px": [320, 240]}, process=False)
