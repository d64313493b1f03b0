"""Where the frame loop runs on the machine: `[loop] realtime_priority` and `[loop] cpu`, applied in the loop's own
thread and undone when the server stops (a script that embeds a server goes on running as it was).

- SCHED_FIFO for the loop's thread (the threads and processes it starts begin ordinary:
  `antarium.core.realtime.set_realtime`);
- a CPU for the loop's thread alone, the rest of the rig moved to the others, re-applied to new threads and child
  processes by `place_threads()` (the server calls it once a second);
- work that may only have the loop's idle time (`beside_loop`: a scene prepared while frames go on) in a thread on
  the loop's CPU, below the real-time loop, so that it never takes the other CPUs from the current scene's
  far-layer builder;
- the GIL switch interval: another thread of ours holding the GIL when a frame is due keeps it until it blocks or
  this interval passes (Python's default, 5 ms, is a whole frame period);
- llvmpipe (software GL) rasterising in the loop's thread when it has a CPU of its own.

Nothing here is required: what the machine refuses is said once through `echo` and the loop runs without it.
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

from antarium.core import realtime

if TYPE_CHECKING:
    from antarium.config import LoopSection

T = TypeVar("T")

#: how long another thread may keep the GIL while the frame loop waits for it (s); Python's default is 5 ms
GIL_SWITCH_INTERVAL_S = 2e-4


class LoopPlacement:
    """`[loop]`'s placement of the calling (frame loop's) thread; `echo` takes the one-line warnings."""

    def __init__(self, loop: LoopSection, echo: Callable[[str], None]) -> None:
        self.priority, self.cpu, self.echo = loop.realtime_priority, loop.cpu, echo
        self._realtime_set = False
        self._isolation: realtime.Isolation | None = None
        self._loop_tid = 0
        self._switch_interval: float | None = None
        self._beside: set[int] = set()      # threads running `beside_loop` work
        self._before: set[int] = set()      # our processes when that work began (those it starts stay with it)
        self._beside_lock = threading.Lock()

    def before_building(self) -> None:
        """In the loop's thread, before the renderer exists: real-time, and llvmpipe's raster threads."""
        if self.priority:
            try:
                realtime.set_realtime(self.priority)
                self._realtime_set = True
            except (AttributeError, PermissionError, OSError) as exc:
                self.echo(f"antarium serve: realtime priority {self.priority} not granted ({exc}); running without it")
        if self.cpu != "off" and len(getattr(os, "sched_getaffinity", lambda _: ())(0)) > 1:
            # llvmpipe (software GL) rasterises in the calling thread: the frame's GL work stays on the loop's own
            # CPU instead of waiting for raster threads on the other (no effect on a GPU driver)
            os.environ.setdefault("LP_NUM_THREADS", "0")

    def before_frames(self) -> None:
        """In the loop's thread, once everything is built: the GIL switch interval and the loop's own CPU."""
        self._switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
        self._isolate()
        self.place_threads()

    def _isolate(self) -> None:
        if self.cpu == "off":
            return
        if not realtime.supported():
            if self.cpu != "auto":
                self.echo("antarium serve: [loop] cpu needs Linux (sched_setaffinity, /proc); running unpinned")
            return
        try:
            self._isolation = realtime.Isolation(self.cpu)
        except ValueError as exc:
            if self.cpu != "auto":  # "auto" on a one-CPU machine: nothing to say
                self.echo(f"antarium serve: {exc}; running unpinned")
            return
        self._loop_tid = threading.get_native_id()

    def place_threads(self) -> None:
        """`[loop] cpu` for the threads and processes started since (they begin with their starter's CPUs);
        what `beside_loop` work started stays beside the loop until that work ends."""
        isolation = self._isolation
        if isolation is not None:
            with self._beside_lock:
                beside = set(self._beside)
                processes = set(self._before) if beside else None
            isolation.apply(self._loop_tid, beside, processes)

    def beside_loop(self, fn: Callable[..., T], *args: Any) -> T:
        """fn(*args) in a thread on the loop's own CPU, with the processes it starts, while the loop is real-time
        there: such work then has only the loop's idle time, and leaves the other CPUs to the rest of the rig (the
        current scene's far-layer builder above all). Elsewhere (no CPU of its own, or an ordinary loop, which it
        would share that CPU with) fn runs in the calling thread. Returns what fn returns, raises what it raises."""
        isolation = self._isolation
        if isolation is None or not self._realtime_set:
            return fn(*args)
        out: dict[str, Any] = {}

        def work() -> None:
            tid = threading.get_native_id()
            with self._beside_lock:
                if not self._beside:
                    self._before = set(realtime.descendants())
                self._beside.add(tid)
            try:
                os.sched_setaffinity(0, {isolation.cpu})
                out["result"] = fn(*args)
            except BaseException as exc:  # noqa: BLE001 - handed to the caller's thread
                out["error"] = exc
            finally:
                with self._beside_lock:
                    self._beside.discard(tid)
                self.place_threads()  # what it started goes to the other CPUs now

        thread = threading.Thread(target=work, name="beside-loop", daemon=True)
        thread.start()
        thread.join()
        if "error" in out:
            raise out["error"]
        return out["result"]

    def release(self) -> None:
        """Undo everything above. Safe to call twice."""
        if self._switch_interval is not None:
            sys.setswitchinterval(self._switch_interval)
            self._switch_interval = None
        isolation, self._isolation = self._isolation, None
        if isolation is not None:
            isolation.release()
        if self._realtime_set:
            self._realtime_set = False
            try:
                realtime.set_ordinary()
            except OSError:
                pass
