"""The panels' LED current settings in the rig config (`[link] brightness_percent`, `dot_correction`): sent by the
server when it opens the link (the link keeps them for a distributor that reboots), checked before anything
starts. Before 2026-11-27 the server sent none: a script had to, and a rebooted distributor lost them."""

import numpy as np
import pytest

from antarium.config import ConfigError, resolve
from antarium.server import Server
from antarium.server.config_check import check_config

DOT = (np.arange(20350 * 2).reshape(20350, 2) % 101).astype(np.uint8)  # frame layout, LED k of pixel i


def _config(tmp_path, **link):
    return resolve({"rig": {"name": "leds"}, "bus": {"enabled": False}, "log": {"dir": str(tmp_path)},
                    "link": {"interface": "virtual", **link}, "loop": {"realtime_priority": 0}})


def _served(config) -> object:
    """The emulator behind the server's link after a few frames."""
    server = Server(config, renderer_factory=None, echo=lambda line: None)
    server.run(frames=5)
    return server.link.emulator


def test_the_rig_configs_brightness_and_dot_correction_reach_the_panels(tmp_path):
    np.save(tmp_path / "dot.npy", DOT)
    emulator = _served(_config(tmp_path, brightness_percent=40, dot_correction=str(tmp_path / "dot.npy")))
    assert (emulator.brightness == 40).all()
    assert (emulator.dot == DOT.reshape(55, 740)).all()


def test_by_default_every_led_runs_at_full_current(tmp_path):
    emulator = _served(_config(tmp_path))
    assert (emulator.brightness == 100).all() and (emulator.dot == 100).all()
    assert emulator.counters["config_updates"] == 56  # 55 panels' dot correction and one brightness, sent


def test_one_percent_for_every_led(tmp_path):
    emulator = _served(_config(tmp_path, dot_correction=70))
    assert (emulator.dot == 70).all()


@pytest.mark.parametrize(("make", "message"), [
    (lambda p: np.save(p, np.full((55, 739), 50)), r"shape \(55, 739\)"),
    (lambda p: np.save(p, np.full((55, 740), 101)), "entry 0 is 101: allowed 0..100 percent"),
    (lambda p: p.write_bytes(b"not numpy"), "cannot be read as a .npy array"),
    (lambda p: None, "cannot be read as a .npy array"),   # no such file
])
def test_a_bad_dot_correction_file_is_named_before_anything_starts(tmp_path, make, message):
    path = tmp_path / "dot.npy"
    make(path)
    with pytest.raises(ConfigError, match=rf"^\[link\] dot_correction: dot correction file '{path}'.*{message}"):
        check_config(_config(tmp_path, dot_correction=str(path)))
