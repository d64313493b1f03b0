"""The servosphere's control loop in a process of its own, for the wall clock: 700 camera frames a second of
tracking and control then never wait for the frame loop's GIL (nor the frame loop for theirs).

The child runs a `ServosphereSource` step after step (paced by its camera) and hands over, every `batch_s`, the
`BallSample`s, the log rows and its status through a pipe; a thread here pushes them on. Both processes read the
same monotonic clock, so the samples' times are the frame loop's.
"""

from __future__ import annotations

import threading
import time
from typing import Any

from antarium.core.childproc import ChildProcess, connection_from_arg
from antarium.core.clock import Clock, MonotonicClock
from antarium.locomotion import BallSample, BufferedSource, check_keywords


class ServosphereProcess(BufferedSource):
    """`options`: the keyword arguments of `source.ServosphereSource` (checked here, used in the child)."""

    def __init__(self, clock: Clock | None = None, start_timeout_s: float = 30.0, batch_s: float = 0.005,
                 **options: Any) -> None:
        from antarium.locomotion.servosphere.source import ServosphereSource

        super().__init__()
        check_keywords("servosphere source", ServosphereSource, options)  # TypeError naming an unknown option, now
        if clock is not None and not isinstance(clock, MonotonicClock):
            raise ValueError(f"the servosphere's own process runs on the monotonic clock, got {type(clock).__name__}")
        self.options, self.start_timeout_s, self.batch_s = options, float(start_timeout_s), float(batch_s)
        self._log = None
        self._status: dict[str, Any] = {"connected": False, "frames": 0}
        self._child: ChildProcess | None = None
        self._conn = None
        self._thread: threading.Thread | None = None

    def use_log(self, log) -> None:
        self._log = log

    def start(self) -> None:
        if self._child is not None:
            return
        self._child = ChildProcess(__name__, connect=True)  # the server has threads (zenoh, logs): never fork it
        self._conn = self._child.conn
        self._conn.send((self.options, self.batch_s))
        if not self._conn.poll(self.start_timeout_s):
            self._kill()
            raise RuntimeError(f"the servosphere process did not start within {self.start_timeout_s} s")
        kind, detail = self._conn.recv()
        if kind != "ready":
            self._kill()
            raise RuntimeError(f"the servosphere process failed to start: {detail}")
        self._status = {"connected": True, "frames": 0}
        self._thread = threading.Thread(target=self._reader, name="servosphere-reader", daemon=True)
        self._thread.start()

    def _reader(self) -> None:
        while True:
            try:
                kind, payload = self._conn.recv()
            except (EOFError, OSError):
                break
            if kind == "error":  # the child's loop stopped on a device error
                with self._lock:
                    self._status = {**self._status, "error": payload}
                break
            if kind != "data":
                break
            samples, rows, status = payload
            for s in samples:
                self._push(BallSample(*s))
            log = self._log
            if log is not None:
                for row in rows:
                    log.add_servosphere(row)
            with self._lock:
                self._status = status
        with self._lock:
            self._status = {**self._status, "connected": False}

    def stop(self) -> None:
        if self._child is None:
            return
        try:
            self._conn.send(("stop", None))
        except OSError:
            pass
        if self._thread is not None:
            self._thread.join(5.0)
        self._child.wait(5.0)
        self._kill()

    def _kill(self) -> None:
        if self._child is not None:
            self._child.kill()
        self._child = None

    def status(self) -> dict[str, Any]:
        with self._lock:
            return dict(self._status)


def servosphere_source(clock: Clock | None = None, process: bool | None = None, **options: Any):
    """The `servosphere` back-end: on the wall clock its control loop runs in a process of its own
    (`process.ServosphereProcess`; `process = false` keeps it in a thread here), on a `SimulatedClock` in `read()`."""
    from antarium.core.clock import SimulatedClock
    from antarium.locomotion.servosphere.source import ServosphereSource

    if process is None:
        process = not isinstance(clock, SimulatedClock)
    if process:
        return ServosphereProcess(clock=clock, **options)
    return ServosphereSource(clock=clock, **options)


class _Rows(list):
    add_servosphere = list.append


def _child_main(conn, options: dict[str, Any], batch_s: float) -> None:
    from antarium.locomotion.servosphere.source import ServosphereSource

    try:
        src = ServosphereSource(clock=MonotonicClock(spin_s=0.0), **options)  # paced by sleeping, not spinning
    except Exception as exc:  # noqa: BLE001 - every start failure goes back to the parent as one line
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    rows = _Rows()
    src.use_log(rows)
    conn.send(("ready", None))
    last = time.monotonic()
    try:
        while not conn.poll():
            try:
                src._run_step()
            except Exception as exc:  # noqa: BLE001 - a device error (pyserial's are OSErrors): to the parent
                src.fail(exc)
                samples = [(s.t, s.seq, s.rotation, s.t_device, s.quality) for s in src.read()]
                conn.send(("data", (samples, list(rows), src.status())))
                conn.send(("error", src.error))
                return
            now = time.monotonic()
            if now - last >= batch_s:
                samples = [(s.t, s.seq, s.rotation, s.t_device, s.quality) for s in src.read()]
                conn.send(("data", (samples, list(rows), src.status())))
                rows.clear()
                last = now
    except (BrokenPipeError, EOFError, ConnectionResetError):  # the pipe's errors only: the parent went away
        pass
    finally:
        src.stop()


if __name__ == "__main__":  # pragma: no cover - the servosphere's own process
    import sys

    _conn = connection_from_arg(sys.argv[1])
    _child_main(_conn, *_conn.recv())
