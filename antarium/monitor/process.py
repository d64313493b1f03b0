"""What `antarium serve` starts for the monitor: the LED stream publisher and (`[monitor] enabled`) its process."""

from __future__ import annotations

import os
import tempfile
from typing import TYPE_CHECKING

from antarium.core.childproc import ChildProcess

if TYPE_CHECKING:
    from antarium.config import RigConfig


def open_led_stream(session, rig: str, config: RigConfig):
    """The `LedPublisher` for `[monitor] leds_every_frames` (None when 0)."""
    every = config.monitor.leds_every_frames
    if not every:
        return None
    from antarium.monitor.led_stream import LedPublisher

    return LedPublisher(session, rig, every)


class MonitorProcess:
    """`antarium monitor` for this rig config, as a process of its own."""

    def __init__(self, config: RigConfig) -> None:
        import tomli_w

        with tempfile.NamedTemporaryFile("w", suffix=".toml", prefix="antarium-monitor-", delete=False) as f:
            f.write(tomli_w.dumps(config.to_toml_dict()))
        self._path = f.name
        self.child = ChildProcess("antarium", ["monitor", "--config", self._path, "--rig", config.rig.name])

    def output(self) -> str:
        """The end of what the monitor printed (its address, or why it stopped)."""
        return self.child.output()

    def close(self, timeout_s: float = 5.0) -> None:
        self.child.stop(timeout_s)
        try:
            os.unlink(self._path)
        except OSError:
            pass


def start_monitor(config: RigConfig) -> MonitorProcess | None:
    """A `MonitorProcess` when `[monitor] enabled = true`, else None."""
    return MonitorProcess(config) if config.monitor.enabled else None
