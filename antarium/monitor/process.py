"""What `antarium serve` starts for the monitor: the LED stream publisher and (`[monitor] enabled`) its process."""

from __future__ import annotations

import os
import tempfile
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from antarium.core.childproc import ChildProcess

if TYPE_CHECKING:
    from antarium.config import RigConfig


def open_led_stream(session, rig: str, config: RigConfig, report: Callable[[str], None] | None = None):
    """The `LedPublisher` for `[monitor] leds_every_frames` (None when 0); `report`: where its failed puts are told."""
    every = config.monitor.leds_every_frames
    if not every:
        return None
    from antarium.monitor.led_stream import LedPublisher

    return LedPublisher(session, rig, every, report=report)


class MonitorProcess:
    """`antarium monitor` for this rig config, as a process of its own."""

    def __init__(self, config: RigConfig) -> None:
        import tomli_w

        with tempfile.NamedTemporaryFile("w", suffix=".toml", prefix="antarium-monitor-", delete=False) as f:
            f.write(tomli_w.dumps(config.to_toml_dict()))
        self._path = f.name
        self._closed = threading.Event()
        self.child = ChildProcess("antarium", ["monitor", "--config", self._path, "--rig", config.rig.name],
                                  end_with_parent=True)  # never left serving the page after a killed server

    def output(self) -> str:
        """The end of what the monitor printed (its address, or why it stopped)."""
        return self.child.output()

    def started(self, timeout_s: float) -> tuple[bool | None, str]:
        """Wait at most `timeout_s` for the monitor to say where it serves its page: (True, that line) once it has,
        (False, why) if it ended first, (None, "") if neither yet."""
        deadline = time.monotonic() + timeout_s
        while True:
            out = self.output()
            for line in out.splitlines():
                if line.startswith("antarium monitor: ") and " at http://" in line:
                    return True, line.strip()
            code = self.child.exitcode
            if code is not None or self._closed.is_set():
                lines = [line for line in self.output().splitlines() if line.strip()]
                why = lines[-1].strip() if lines else "it printed nothing"
                return False, f"antarium serve: the monitor stopped at its start (exit code {code}): {why}"
            if time.monotonic() >= deadline:
                return None, ""
            self._closed.wait(0.05)

    def report(self, echo: Callable[[str], None], timeout_s: float = 60.0) -> threading.Thread:
        """A thread that echoes the monitor's address once it listens, or why it stopped if it ends before (e.g.
        its port in use), or that it said neither within `timeout_s`; then, if the monitor ends while the server
        runs (killed, crashed), one line with its exit code and last output (checked twice a second). Never
        holds up the server."""
        def run() -> None:
            ok, line = self.started(timeout_s)
            if self._closed.is_set():
                return
            if ok is None:
                line = (f"antarium serve: the monitor has not said where it serves its page within {timeout_s:g} s; "
                        f"its output so far: {self.output().strip()[-500:] or '(none)'}")
            echo(line)
            if ok is False:
                return
            while not self._closed.wait(0.5):
                code = self.child.exitcode
                if code is not None and not self._closed.is_set():  # close() sets _closed before it stops the child
                    after = [ln.strip() for ln in self.output().split(line, 1)[-1].splitlines() if ln.strip()]
                    echo(f"antarium serve: the monitor stopped while the server runs (exit code {code}): "
                         f"{after[-1] if after else 'it printed nothing more'}; the server goes on without it (its "
                         "page is gone)")
                    return

        thread = threading.Thread(target=run, name="monitor-report", daemon=True)
        thread.start()
        return thread

    def close(self, timeout_s: float = 5.0) -> None:
        self._closed.set()
        self.child.stop(timeout_s)
        try:
            os.unlink(self._path)
        except OSError:
            pass


def start_monitor(config: RigConfig) -> MonitorProcess | None:
    """A `MonitorProcess` when `[monitor] enabled = true`, else None."""
    return MonitorProcess(config) if config.monitor.enabled else None
