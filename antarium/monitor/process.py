"""What `antarium serve` starts for the monitor: the LED stream publisher and (`[monitor] enabled`) its process."""

from __future__ import annotations

import subprocess
import sys
import tempfile
from typing import Any

from antarium.monitor.settings import monitor_settings


def open_led_stream(session, rig: str, config: dict[str, Any]):
    """The `LedPublisher` for `[monitor] leds_every` (None when 0)."""
    every = monitor_settings(config)["leds_every"]
    if not every:
        return None
    from antarium.monitor.led_stream import LedPublisher

    return LedPublisher(session, rig, every)


class MonitorProcess:
    """`antarium monitor` for this rig config, as a process of its own (its output goes to the server's)."""

    def __init__(self, config: dict[str, Any]) -> None:
        import tomli_w

        self._file = tempfile.NamedTemporaryFile("w", suffix=".toml", prefix="antarium-monitor-", delete=False)
        self._file.write(tomli_w.dumps(config))
        self._file.close()
        self.proc = subprocess.Popen([sys.executable, "-m", "antarium", "monitor", "--config", self._file.name,
                                      "--rig", config["rig"]["name"]], stdin=subprocess.DEVNULL)

    def close(self, timeout_s: float = 5.0) -> None:
        import os

        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout_s)
        try:
            os.unlink(self._file.name)
        except OSError:
            pass


def start_monitor(config: dict[str, Any]) -> MonitorProcess | None:
    """A `MonitorProcess` when `[monitor] enabled = true`, else None."""
    return MonitorProcess(config) if monitor_settings(config)["enabled"] else None
